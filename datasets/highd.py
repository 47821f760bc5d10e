"""highD recordings: read, validate, write, and convert to the road frame.

Files of recording ``XX``: ``XX_tracks.csv``, ``XX_tracksMeta.csv``,
``XX_recordingMeta.csv`` (columns in :mod:`datasets.highd_columns`). Reading validates
every column; a missing file, a missing column or an unparsable value raises an error that
names the file, the column and the row (0-based data row; the CSV line is row + 2).

Road frame (DESIGN.md), applied once in :func:`road_frame`:

- centre = upper-left corner + half the box: ``xc = x + width / 2``, ``yc = y + height / 2``
  (``width`` is the vehicle length, ``height`` its width);
- image y points down; driving direction 2 (lower lanes) drives towards +x, so
  ``x_road = xc``, ``y_road = -yc``, ``vx = xVelocity``, ``vy = -yVelocity``;
- driving direction 1 (upper lanes) drives towards -x and is rotated by 180 degrees:
  ``x_road = -xc``, ``y_road = yc``, ``vx = -xVelocity``, ``vy = yVelocity``.

So x always grows along the driving direction and y to the driver's left; lane markings
are converted the same way (:meth:`HighDRecording.marking_road`). Time ``t = frame /
frameRate``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from datasets import highd_columns as hc
from datasets.errors import FormatError

__all__ = [
    "ROAD_COLUMNS",
    "HighDRecording",
    "find_recordings",
    "read_highd",
    "road_frame",
    "write_highd",
]


def _show(value: object) -> str:
    """A cell value for an error message: strings quoted, numbers plain."""
    if isinstance(value, str):
        return repr(value)
    item = getattr(value, "item", None)
    return str(item() if callable(item) else value)

#: columns of :func:`road_frame`
ROAD_COLUMNS: tuple[str, ...] = (
    "id", "frame", "t", "x", "y", "vx", "vy", "ax", "ay", "length", "width",
    "lane_id", "direction", "preceding_id", "following_id",
)


def _parse_markings(text: object, where: str) -> np.ndarray:
    try:
        values = np.array([float(s) for s in str(text).split(";") if s.strip()])
    except ValueError:
        raise FormatError(f"{where}: expected numbers separated by ';', got {text!r}") from None
    if values.size < 2 or not np.isfinite(values).all() or (np.diff(values) <= 0).any():
        raise FormatError(f"{where}: expected >= 2 increasing lane markings, got {text!r}")
    return values


@dataclass
class HighDRecording:
    """One highD recording: the three tables with highD's own column names and units.

    Attributes
    ----------
    name : str
        The recording prefix ``XX`` (file names are ``XX_tracks.csv`` ...).
    recording_meta : DataFrame of shape (1, 15)
    tracks_meta : DataFrame of shape (n_vehicles, 16)
    tracks : DataFrame of shape (n_rows, 25)
    """

    name: str
    recording_meta: pd.DataFrame
    tracks_meta: pd.DataFrame
    tracks: pd.DataFrame

    @property
    def frame_rate(self) -> float:
        """Frames per second (highD: 25)."""
        return float(self.recording_meta[hc.FRAME_RATE].iloc[0])

    def driven(self) -> tuple[float, float]:
        """The recording's exposure per vehicle, summed over its tracked vehicles: seconds
        each was tracked on the section (``numFrames / frameRate``) and metres it drove
        there (``traveledDistance``), from ``tracksMeta``. These are vehicle-seconds and
        vehicle-metres: every cut-in in front of any tracked vehicle was observable in
        them (highD's own ``totalDrivenTime`` / ``totalDrivenDistance`` of
        ``recordingMeta`` are the same sums, rounded)."""
        seconds = float(self.tracks_meta[hc.NUM_FRAMES].to_numpy(dtype=np.float64).sum())
        metres = float(np.abs(self.tracks_meta[hc.TRAVELED_DISTANCE]
                              .to_numpy(dtype=np.float64)).sum())
        return seconds / self.frame_rate, metres

    @property
    def is_synthetic(self) -> bool:
        """True for recordings written by :mod:`datasets.synth`."""
        return str(self.recording_meta[hc.MONTH].iloc[0]) == hc.SYNTHETIC_MARK

    def markings(self, direction: int) -> np.ndarray:
        """Lane markings of a driving direction in image y (m), increasing."""
        col = hc.UPPER_LANE_MARKINGS if direction == 1 else hc.LOWER_LANE_MARKINGS
        return _parse_markings(self.recording_meta[col].iloc[0], f"{self.name} {col}")

    def all_markings(self) -> np.ndarray:
        """Upper then lower lane markings in image y (m). Lane id k lies between the
        markings of 0-based index k - 2 and k - 1 (highD numbering)."""
        return np.concatenate([self.markings(1), self.markings(2)])

    def lane_direction(self, lane_id: int) -> int:
        """Driving direction (1 or 2) of a lane id."""
        n_upper = len(self.markings(1))
        return 1 if lane_id <= n_upper else 2

    def lane_width(self, lane_id: int) -> float:
        """Width in m of lane ``lane_id``."""
        m = self.all_markings()
        if not 2 <= lane_id <= len(m) or lane_id == len(self.markings(1)) + 1:
            raise FormatError(f"{self.name}: lane id {lane_id} is not a driving lane")
        return float(m[lane_id - 1] - m[lane_id - 2])

    def marking_road(self, lane_a: int, lane_b: int) -> float:
        """Road-frame y (m) of the marking between adjacent lanes ``lane_a``, ``lane_b``."""
        if abs(lane_a - lane_b) != 1:
            raise FormatError(f"{self.name}: lanes {lane_a} and {lane_b} are not adjacent")
        y_img = float(self.all_markings()[min(lane_a, lane_b) - 1])
        return y_img if self.lane_direction(lane_a) == 1 else -y_img


def _validate(frame: pd.DataFrame, path: Path, columns: tuple[str, ...],
              ints: frozenset[str], texts: frozenset[str]) -> pd.DataFrame:
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise FormatError(f"{path}: missing column(s) {', '.join(missing)}")
    if len(frame) == 0:
        raise FormatError(f"{path}: no rows")
    out = frame.loc[:, list(columns)].copy()
    out.index = pd.RangeIndex(len(out))
    for col in columns:
        raw = out[col]
        if col in texts:
            if raw.isna().any():
                row = int(np.flatnonzero(raw.isna().to_numpy())[0])
                raise FormatError(f"{path}: column {col!r}, row {row}: empty value")
            out[col] = raw.astype(str)
            continue
        if pd.api.types.is_numeric_dtype(raw.dtype) and not pd.api.types.is_bool_dtype(raw.dtype):
            values = raw.to_numpy(dtype=np.float64)
            bad = ~np.isfinite(values)
        else:
            values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64)
            bad = ~np.isfinite(values)
        if col in ints:
            bad |= np.isfinite(values) & (values != np.round(values))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            kind = "an integer" if col in ints else "a finite number"
            raise FormatError(
                f"{path}: column {col!r}, row {row} (line {row + 2}): value "
                f"{_show(raw.iloc[row])} is not {kind}"
            )
        out[col] = values.astype(np.int64) if col in ints else values
    return out


def _read(path: Path, columns: tuple[str, ...], ints: frozenset[str], texts: frozenset[str],
          progress: bool = False) -> pd.DataFrame:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing highD file")
    str_cols = {c: str for c in texts}
    try:
        if progress:
            from tqdm import tqdm

            chunks = []
            with tqdm(desc=f"read {path.name}", unit="row", unit_scale=True) as bar:
                for chunk in pd.read_csv(path, chunksize=100_000, dtype=str_cols):
                    chunks.append(chunk)
                    bar.update(len(chunk))
            frame = pd.concat(chunks, ignore_index=True) if chunks else pd.DataFrame()
        else:
            frame = pd.read_csv(path, dtype=str_cols)
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path}: not a readable CSV file ({exc})") from None
    return _validate(frame, path, columns, ints, texts)


def find_recordings(path: str | Path) -> list[Path]:
    """Recording prefixes (``dir/XX``) under a directory, or of one of the three files."""
    p = Path(path)
    if p.is_dir():
        found = sorted(p.glob(f"*{hc.TRACKS_SUFFIX}"))
        if not found:
            raise FileNotFoundError(f"{p}: no *{hc.TRACKS_SUFFIX} file (not a highD folder)")
        return [f.parent / f.name[: -len(hc.TRACKS_SUFFIX)] for f in found]
    for suffix in (hc.TRACKS_SUFFIX, hc.TRACKS_META_SUFFIX, hc.RECORDING_META_SUFFIX):
        if p.name.endswith(suffix):
            return [p.parent / p.name[: -len(suffix)]]
    raise FileNotFoundError(
        f"{p}: not a highD folder or an XX_tracks.csv / XX_tracksMeta.csv / "
        "XX_recordingMeta.csv file"
    )


def read_highd(prefix: str | Path, progress: bool = False) -> HighDRecording:
    """Read and validate recording ``prefix`` (a path ``dir/XX`` without the suffixes).

    Also checks the cross-file facts extraction relies on: every track id of
    ``XX_tracks.csv`` has a row in ``XX_tracksMeta.csv`` with ``drivingDirection`` 1 or 2,
    and (id, frame) pairs are unique.
    """
    p = Path(prefix)
    rec_meta = _read(Path(f"{p}{hc.RECORDING_META_SUFFIX}"), hc.RECORDING_META_COLUMNS,
                     hc.RECORDING_META_INT, hc.RECORDING_META_TEXT)
    meta_path = Path(f"{p}{hc.TRACKS_META_SUFFIX}")
    meta = _read(meta_path, hc.TRACKS_META_COLUMNS, hc.TRACKS_META_INT, hc.TRACKS_META_TEXT)
    tracks_path = Path(f"{p}{hc.TRACKS_SUFFIX}")
    tracks = _read(tracks_path, hc.TRACKS_COLUMNS, hc.TRACKS_INT, frozenset(), progress)
    rec = HighDRecording(p.name, rec_meta, meta, tracks)
    rec.markings(1)
    rec.markings(2)
    if rec.frame_rate <= 0:
        raise FormatError(f"{p}{hc.RECORDING_META_SUFFIX}: column 'frameRate', row 0: must be > 0")
    bad_dir = ~meta[hc.DRIVING_DIRECTION].isin([1, 2]).to_numpy()
    if bad_dir.any():
        row = int(np.flatnonzero(bad_dir)[0])
        raise FormatError(f"{meta_path}: column 'drivingDirection', row {row}: expected 1 or 2")
    if meta[hc.TRACK_ID].duplicated().any():
        row = int(np.flatnonzero(meta[hc.TRACK_ID].duplicated().to_numpy())[0])
        raise FormatError(f"{meta_path}: column 'id', row {row}: duplicate track id")
    known = tracks[hc.TRACK_ID].isin(meta[hc.TRACK_ID]).to_numpy()
    if not known.all():
        row = int(np.flatnonzero(~known)[0])
        raise FormatError(
            f"{tracks_path}: column 'id', row {row}: track id {tracks[hc.TRACK_ID].iloc[row]} "
            f"has no row in {meta_path.name}"
        )
    dup = tracks.duplicated([hc.TRACK_ID, hc.FRAME]).to_numpy()
    if dup.any():
        row = int(np.flatnonzero(dup)[0])
        raise FormatError(f"{tracks_path}: column 'frame', row {row}: repeated (id, frame)")
    return rec


def write_highd(recording: HighDRecording, directory: str | Path,
                name: str | None = None) -> list[Path]:
    """Write the three CSV files of ``recording`` into ``directory`` (created if needed).

    Floats are written with Python's shortest round-trip repr, so :func:`read_highd` gives
    back the same tables bit for bit. Returns the three paths.
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    stem = name or recording.name
    paths = [d / f"{stem}{hc.TRACKS_SUFFIX}", d / f"{stem}{hc.TRACKS_META_SUFFIX}",
             d / f"{stem}{hc.RECORDING_META_SUFFIX}"]
    frames = [
        _validate(recording.tracks, paths[0], hc.TRACKS_COLUMNS, hc.TRACKS_INT, frozenset()),
        _validate(recording.tracks_meta, paths[1], hc.TRACKS_META_COLUMNS, hc.TRACKS_META_INT,
                  hc.TRACKS_META_TEXT),
        _validate(recording.recording_meta, paths[2], hc.RECORDING_META_COLUMNS,
                  hc.RECORDING_META_INT, hc.RECORDING_META_TEXT),
    ]
    for frame, path in zip(frames, paths, strict=True):
        frame.to_csv(path, index=False)
    return paths


def road_frame(recording: HighDRecording) -> pd.DataFrame:
    """Tracks in the road frame of their driving direction (see the module docstring).

    Returns
    -------
    DataFrame
        Columns :data:`ROAD_COLUMNS`: ``id``, ``frame``, ``t`` (s), centre ``x``, ``y`` (m),
        ``vx``, ``vy`` (m/s), ``ax``, ``ay`` (m/s^2), ``length``, ``width`` (m), ``lane_id``,
        ``direction``, ``preceding_id``, ``following_id``; sorted by id then frame.
    """
    tr = recording.tracks
    meta = recording.tracks_meta.set_index(hc.TRACK_ID)
    direction = meta[hc.DRIVING_DIRECTION].reindex(tr[hc.TRACK_ID].to_numpy()).to_numpy()
    flip = np.where(direction == 1, -1.0, 1.0)
    xc = tr[hc.X].to_numpy() + 0.5 * tr[hc.WIDTH].to_numpy()
    yc = tr[hc.Y].to_numpy() + 0.5 * tr[hc.HEIGHT].to_numpy()
    out = pd.DataFrame({
        "id": tr[hc.TRACK_ID].to_numpy(),
        "frame": tr[hc.FRAME].to_numpy(),
        "t": tr[hc.FRAME].to_numpy() / recording.frame_rate,
        "x": flip * xc,
        "y": -flip * yc,
        "vx": flip * tr[hc.X_VELOCITY].to_numpy(),
        "vy": -flip * tr[hc.Y_VELOCITY].to_numpy(),
        "ax": flip * tr[hc.X_ACCELERATION].to_numpy(),
        "ay": -flip * tr[hc.Y_ACCELERATION].to_numpy(),
        "length": tr[hc.WIDTH].to_numpy(),
        "width": tr[hc.HEIGHT].to_numpy(),
        "lane_id": tr[hc.LANE_ID].to_numpy(),
        "direction": direction,
        "preceding_id": tr[hc.PRECEDING_ID].to_numpy(),
        "following_id": tr[hc.FOLLOWING_ID].to_numpy(),
    })
    return out.sort_values(["id", "frame"], kind="stable").reset_index(drop=True)
