"""Every column name of the three highD files, declared once (as highD's own read_csv.py does).

highD (Krajewski et al., 2018) stores one recording as ``XX_tracks.csv`` (one row per
vehicle per frame), ``XX_tracksMeta.csv`` (one row per vehicle) and
``XX_recordingMeta.csv`` (one row). Image frame: x to the right, y downwards, (x, y) the
upper-left corner of the bounding box, ``width`` the box's extent along x (the vehicle
length) and ``height`` its extent along y (the vehicle width). Ids 0 mean "none".
"""

from __future__ import annotations

__all__ = [
    "RECORDING_META_COLUMNS",
    "RECORDING_META_INT",
    "RECORDING_META_TEXT",
    "TRACKS_COLUMNS",
    "TRACKS_INT",
    "TRACKS_META_COLUMNS",
    "TRACKS_META_INT",
    "TRACKS_META_TEXT",
]

# --- XX_tracks.csv
FRAME = "frame"
TRACK_ID = "id"
X = "x"
Y = "y"
WIDTH = "width"
HEIGHT = "height"
X_VELOCITY = "xVelocity"
Y_VELOCITY = "yVelocity"
X_ACCELERATION = "xAcceleration"
Y_ACCELERATION = "yAcceleration"
FRONT_SIGHT_DISTANCE = "frontSightDistance"
BACK_SIGHT_DISTANCE = "backSightDistance"
DHW = "dhw"
THW = "thw"
TTC = "ttc"
PRECEDING_X_VELOCITY = "precedingXVelocity"
PRECEDING_ID = "precedingId"
FOLLOWING_ID = "followingId"
LEFT_PRECEDING_ID = "leftPrecedingId"
LEFT_ALONGSIDE_ID = "leftAlongsideId"
LEFT_FOLLOWING_ID = "leftFollowingId"
RIGHT_PRECEDING_ID = "rightPrecedingId"
RIGHT_ALONGSIDE_ID = "rightAlongsideId"
RIGHT_FOLLOWING_ID = "rightFollowingId"
LANE_ID = "laneId"

TRACKS_COLUMNS: tuple[str, ...] = (
    FRAME, TRACK_ID, X, Y, WIDTH, HEIGHT, X_VELOCITY, Y_VELOCITY, X_ACCELERATION,
    Y_ACCELERATION, FRONT_SIGHT_DISTANCE, BACK_SIGHT_DISTANCE, DHW, THW, TTC,
    PRECEDING_X_VELOCITY, PRECEDING_ID, FOLLOWING_ID, LEFT_PRECEDING_ID, LEFT_ALONGSIDE_ID,
    LEFT_FOLLOWING_ID, RIGHT_PRECEDING_ID, RIGHT_ALONGSIDE_ID, RIGHT_FOLLOWING_ID, LANE_ID,
)
TRACKS_INT: frozenset[str] = frozenset({
    FRAME, TRACK_ID, PRECEDING_ID, FOLLOWING_ID, LEFT_PRECEDING_ID, LEFT_ALONGSIDE_ID,
    LEFT_FOLLOWING_ID, RIGHT_PRECEDING_ID, RIGHT_ALONGSIDE_ID, RIGHT_FOLLOWING_ID, LANE_ID,
})

# --- XX_tracksMeta.csv (also uses TRACK_ID, WIDTH, HEIGHT)
INITIAL_FRAME = "initialFrame"
FINAL_FRAME = "finalFrame"
NUM_FRAMES = "numFrames"
CLASS = "class"
DRIVING_DIRECTION = "drivingDirection"
TRAVELED_DISTANCE = "traveledDistance"
MIN_X_VELOCITY = "minXVelocity"
MAX_X_VELOCITY = "maxXVelocity"
MEAN_X_VELOCITY = "meanXVelocity"
MIN_DHW = "minDHW"
MIN_THW = "minTHW"
MIN_TTC = "minTTC"
NUMBER_LANE_CHANGES = "numLaneChanges"

TRACKS_META_COLUMNS: tuple[str, ...] = (
    TRACK_ID, WIDTH, HEIGHT, INITIAL_FRAME, FINAL_FRAME, NUM_FRAMES, CLASS,
    DRIVING_DIRECTION, TRAVELED_DISTANCE, MIN_X_VELOCITY, MAX_X_VELOCITY, MEAN_X_VELOCITY,
    MIN_DHW, MIN_THW, MIN_TTC, NUMBER_LANE_CHANGES,
)
TRACKS_META_INT: frozenset[str] = frozenset({
    TRACK_ID, INITIAL_FRAME, FINAL_FRAME, NUM_FRAMES, DRIVING_DIRECTION, NUMBER_LANE_CHANGES,
})
TRACKS_META_TEXT: frozenset[str] = frozenset({CLASS})

# --- XX_recordingMeta.csv
RECORDING_ID = "id"
FRAME_RATE = "frameRate"
LOCATION_ID = "locationId"
SPEED_LIMIT = "speedLimit"
MONTH = "month"
WEEKDAY = "weekDay"
START_TIME = "startTime"
DURATION = "duration"
TOTAL_DRIVEN_DISTANCE = "totalDrivenDistance"
TOTAL_DRIVEN_TIME = "totalDrivenTime"
N_VEHICLES = "numVehicles"
N_CARS = "numCars"
N_TRUCKS = "numTrucks"
UPPER_LANE_MARKINGS = "upperLaneMarkings"
LOWER_LANE_MARKINGS = "lowerLaneMarkings"

RECORDING_META_COLUMNS: tuple[str, ...] = (
    RECORDING_ID, FRAME_RATE, LOCATION_ID, SPEED_LIMIT, MONTH, WEEKDAY, START_TIME, DURATION,
    TOTAL_DRIVEN_DISTANCE, TOTAL_DRIVEN_TIME, N_VEHICLES, N_CARS, N_TRUCKS,
    UPPER_LANE_MARKINGS, LOWER_LANE_MARKINGS,
)
RECORDING_META_INT: frozenset[str] = frozenset({
    RECORDING_ID, LOCATION_ID, N_VEHICLES, N_CARS, N_TRUCKS,
})
RECORDING_META_TEXT: frozenset[str] = frozenset({
    MONTH, WEEKDAY, START_TIME, UPPER_LANE_MARKINGS, LOWER_LANE_MARKINGS,
})

#: file-name suffixes of one recording ``XX``
TRACKS_SUFFIX = "_tracks.csv"
TRACKS_META_SUFFIX = "_tracksMeta.csv"
RECORDING_META_SUFFIX = "_recordingMeta.csv"

#: value of ``month`` and ``weekDay`` in recordings made by :mod:`datasets.synth`
SYNTHETIC_MARK = "SYNTHETIC"
