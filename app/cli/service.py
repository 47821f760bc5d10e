"""``scengen serve`` and ``scengen catalogue create|resume|status|scenarios|list|export``.

The catalogue commands work on the local store (``SCENGEN_DATA_DIR``,
``SCENGEN_DATABASE_URL``) — the same one the service uses — and run jobs in the
foreground on the configured executor (local pool, or Dask when
``SCENGEN_DASK_SCHEDULER`` is set), with a progress bar on stderr. A ``create`` that is
interrupted (Ctrl-C, kill) leaves its finished chunks stored; ``resume ID`` (or a service
start) completes it with the same result an uninterrupted run gives.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli.options import (
    CliError,
    add_constraints,
    add_data_dir,
    add_n,
    add_out,
    add_quiet,
    add_sampler,
    store_label,
)
from app.cli.sampling import StageBars

if TYPE_CHECKING:
    from app.context import ServiceContext
    from app.jobs.joblock import JobBusy


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    serve = subparsers.add_parser(
        "serve", help="start the HTTP service",
        description="Start the HTTP service on the store (--data-dir, else SCENGEN_DATA_DIR, "
        "else ~/.local/share/scengen). Host and port default to SCENGEN_HOST and "
        "SCENGEN_PORT (127.0.0.1:8000).")
    serve.add_argument("--host", default=None,
                       help="address to listen on (default: SCENGEN_HOST, else 127.0.0.1)")
    serve.add_argument("--port", type=int, default=None,
                       help="port to listen on (default: SCENGEN_PORT, else 8000)")
    serve.add_argument("--log-level", default="info",
                       choices=["critical", "error", "warning", "info", "debug"],
                       help="uvicorn's log level (info)")
    add_data_dir(serve)
    serve.set_defaults(func=_serve)

    cat = subparsers.add_parser(
        "catalogue", help="test catalogues in the local store",
        description="Catalogues in the store the service uses (--data-dir, else "
        "SCENGEN_DATA_DIR, else ~/.local/share/scengen; SCENGEN_DATABASE_URL for another "
        "database).")
    sub = cat.add_subparsers(dest="catalogue_command", metavar="ACTION", required=True)

    create = sub.add_parser("create", help="generate a catalogue (foreground, resumable)")
    add_n(create, default=None, what="scenarios")
    create.add_argument("--seed", type=int, default=0, help="seed (0)")
    add_constraints(create, default_text="ttc<3")
    create.add_argument("--model", default="default", help="model id (default: the "
                        "embedded data's model)")
    add_sampler(create)
    create.add_argument("--no-score", action="store_true", help="skip the TTR risk")
    create.add_argument("--wagner-scan", action="store_true",
                        help="also alarm_time, risk_peak and Wagner's risk at the crossing "
                             "(about 2/3 of the scoring time; null otherwise)")
    create.add_argument("--chunk-size", type=int, default=None,
                        help="scenarios per stored chunk (default: SCENGEN_CHUNK_SIZE)")
    add_quiet(create)
    add_data_dir(create)
    create.set_defaults(func=_create)

    resume = sub.add_parser("resume", help="finish an interrupted catalogue")
    resume.add_argument("id", help="catalogue id")
    add_quiet(resume)
    add_data_dir(resume)
    resume.set_defaults(func=_resume)

    status = sub.add_parser("status", help="print a catalogue's status as JSON")
    status.add_argument("id", help="catalogue id")
    add_data_dir(status)
    status.set_defaults(func=_status)

    scen = sub.add_parser("scenarios", help="a catalogue's scenarios, ranked and filtered "
                          "(JSON lines, one record each)")
    scen.add_argument("id", help="catalogue id")
    scen.add_argument("--order-by", default="btn",
                      help="index or a numeric field (btn, a_req, ttr_true, ttc, risk, ...); "
                           "default btn")
    scen.add_argument("--asc", action="store_true",
                      help="ascending (default: descending, except for index)")
    scen.add_argument("--class", dest="classes", action="append", default=[],
                      help="keep this class (repeatable): no_conflict, preventable, "
                           "unpreventable, unavoidable")
    scen.add_argument("--filter", dest="filters", action="append", default=[],
                      metavar="NAME=VALUE",
                      help="as the API: btn_min=0.7, ttr_true_max=1, r157_cc_collision=false")
    scen.add_argument("--limit", type=int, default=20, help="rows to print (20)")
    scen.add_argument("--offset", type=int, default=0, help="rows to skip first (0)")
    add_data_dir(scen)
    scen.set_defaults(func=_scenarios)

    listing = sub.add_parser("list", help="list the catalogues")
    add_data_dir(listing)
    listing.set_defaults(func=_list)

    export = sub.add_parser("export", help="export a finished catalogue")
    export.add_argument("id", help="catalogue id")
    export.add_argument("--format", default="jsonl",
                        choices=["jsonl", "csv", "parquet", "xosc", "commonroad"],
                        help="file format (jsonl; xosc, commonroad: zips of scenario files)")
    add_out(export, required=True, help="output file")
    export.add_argument("--mode", default=None, choices=["test", "replay"],
                        help="xosc only: test (default; the ego is the system under test) "
                             "or replay (both vehicles scripted)")
    add_quiet(export)
    add_data_dir(export)
    export.set_defaults(func=_export)


def _serve(args: argparse.Namespace) -> int:
    from app.settings import get_settings

    settings = get_settings()
    host = args.host if args.host is not None else settings.host
    port = args.port if args.port is not None else settings.port
    if not 1 <= port <= 65535:
        raise CliError(f"--port: must be between 1 and 65535, got {port}")
    # the store before the port: a second service on it (whatever its port) stops here,
    # naming the one that holds it (and so where it listens), before anything is resumed
    lock = _lock_store(Path(settings.data_dir).expanduser().resolve(), _url(host, port))
    _logging()
    key = settings.api_key.get_secret_value() if settings.api_key is not None else ""
    if not _is_loopback(host) and not key:
        print(f"scengen serve: WARNING: listening on {host}, beyond this machine's loopback, "
              "with no API key: anyone who can reach it may start and delete jobs. Set "
              "SCENGEN_API_KEY (e.g. SCENGEN_API_KEY=$(openssl rand -hex 24)) or bind to "
              "127.0.0.1", file=sys.stderr, flush=True)
    os.environ["SCENGEN_HOST"] = host  # the app's settings (trusted hosts) see the bind
    get_settings.cache_clear()
    try:
        _listen_and_serve(host, port, args.log_level)
    finally:
        os.close(lock)  # (the OS releases it as well when the process dies, even by SIGKILL)
    return 0


#: the file in the data dir that a running ``scengen serve`` holds locked; it says which
#: process holds it and where it listens ("PID URL")
LOCK_FILE = "serve.lock"


def _lock_store(data_dir: Path, url: str) -> int:
    """Lock the store in ``data_dir`` for ``scengen serve`` (an exclusive ``flock`` on
    ``LOCK_FILE``; its descriptor is returned, the lock lasts until it is closed or the
    process ends), or a CliError naming the service that holds it. Each service resumes
    the store's unfinished jobs when it starts: two on one store ran the same jobs twice
    at once."""
    import fcntl

    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(data_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise CliError(f"--data-dir: cannot use the store {data_dir}: "
                       f"{exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 4096, 0).decode("utf-8", "replace").split()
        os.close(fd)
        who = f" (pid {holder[0]}, {holder[1]})" if len(holder) == 2 else ""
        raise CliError(f"--data-dir: the store {data_dir} is in use by another scengen "
                       f"serve{who}; stop it or choose another --data-dir") from None
    except OSError as exc:
        os.close(fd)
        raise CliError(f"--data-dir: cannot lock the store {data_dir}: "
                       f"{exc.strerror or exc}") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()} {url}\n".encode(), 0)
    return fd


def _url(host: str, port: int) -> str:
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}"


def _listen_and_serve(host: str, port: int, log_level: str) -> None:
    """Listen on ``host:port`` first, then start the app on that socket. The app's start
    resumes the store's unfinished jobs: a second service pointed at a port already in
    use must stop before that (it used to resume them, run them beside the live service
    for the seconds until uvicorn found the port taken, and only then exit)."""
    import uvicorn

    sock = _bind(host, port)
    # uvicorn says where it listens only for sockets it binds itself
    print(f"scengen serve: listening on {_url(host, port)}", file=sys.stderr, flush=True)
    config = uvicorn.Config("app.main:app", host=host, port=port, log_level=log_level)
    uvicorn.Server(config).run(sockets=[sock])


def _bind(host: str, port: int) -> socket.socket:
    """A socket bound to ``host:port``, or a CliError naming the option."""
    try:
        family, kind, proto, _, addr = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)[0]
        sock = socket.socket(family, kind, proto)
    except OSError as exc:
        raise CliError(f"--host: cannot listen on {host}: {exc.strerror or exc}") from None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn does
        sock.bind(addr)
    except OSError as exc:
        sock.close()
        raise CliError(f"--port: cannot listen on {host}:{port}: {exc.strerror or exc} "
                       "(another service there? --port or SCENGEN_PORT picks another)"
                       ) from None
    return sock


def _is_loopback(host: str) -> bool:
    """Whether a bind address is only reachable from this machine."""
    import ipaddress

    name = host.strip().strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def _logging() -> None:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger("alembic").setLevel(logging.WARNING)


def _context(load_defaults: bool = True) -> ServiceContext:
    """The store's context. Commands that only read (``load_defaults=False``) never create
    a store: where there is none they say where they looked."""
    from app.services import store
    from app.settings import get_settings

    settings = get_settings()
    if not load_defaults and not settings.database_url:
        db_file = Path(settings.data_dir).resolve() / "scengen.db"
        if not db_file.is_file():
            raise CliError(f"no store at {db_file.parent} (set --data-dir or "
                           "SCENGEN_DATA_DIR; the service and 'catalogue create' make one)")
    return store.open_context(settings, load_defaults=load_defaults)


def _context_with_pool(load_defaults: bool = True) -> ServiceContext:
    """``_context`` with the pool's workers started (and warming up) first: their start
    and kernel loading (about 2 s) overlap this process's imports, store opening and
    model loading instead of following them (issue 25 item 7)."""
    from app.jobs.executors import make_executor  # imports no sampler, sklearn or numba
    from app.settings import get_settings

    settings = get_settings()
    executor = make_executor(dask_scheduler=settings.dask_scheduler,
                             local_workers=settings.local_workers)
    executor.warm()
    try:
        ctx = _context(load_defaults)
    except BaseException:
        executor.close()
        raise
    ctx.adopt_executor(executor)
    return ctx


def _in_store(exc: LookupError) -> CliError:
    """A "not found" that names the store it searched."""
    return CliError(f"{exc.args[0] if exc.args else exc} in the store at {store_label()}")


def _left_to_its_runner(catalogue_id: str, busy: JobBusy) -> CliError:
    return CliError(f"catalogue {catalogue_id} is being run by another process on this "
                    f"store (pid {busy.pid or 'unknown'}); left to it: resume it here only "
                    "if that process ends before the job does")


def _run(ctx: ServiceContext, catalogue_id: str, show_progress: bool) -> int:
    from tqdm import tqdm

    from app.jobs.joblock import JobBusy
    from app.services import catalogues

    bar: Any = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if not show_progress:
            return
        if bar is None:
            bar = tqdm(total=total, initial=done, unit="scenario", file=sys.stderr,
                       desc=catalogue_id)
        else:
            bar.update(done - bar.n)

    stages = StageBars(quiet=not show_progress)  # the P(A) estimate's stages
    # the pool's workers were started and are warming up since the command began
    # (_context_with_pool): the service's are warm, the CLI's were once started only when
    # the first chunk was sent (issue 25: a 1,000 catalogue 18.5 s from the CLI, 8.4 s
    # from the service)
    try:
        status = catalogues.run(ctx, catalogue_id, progress=progress,
                                note=(lambda text: tqdm.write(text, file=sys.stderr))
                                if show_progress else None, stage=stages)
    except LookupError as exc:
        raise _in_store(exc) from None
    except JobBusy as busy:
        raise _left_to_its_runner(catalogue_id, busy) from None
    except KeyboardInterrupt:
        # Ctrl-C: the catalogue says "cancelled" (not a stale "running") and how to go on
        stored, n = catalogues.mark_cancelled(ctx, catalogue_id)
        if bar is not None:
            bar.close()
            bar = None
        print(f"scengen: catalogue {catalogue_id} cancelled with {stored} of {n} scenarios "
              f"stored; resume it with: scengen catalogue resume {catalogue_id}",
              file=sys.stderr)
        return 130
    finally:
        stages.close()
        if bar is not None:
            bar.close()
    print(json.dumps({"id": catalogue_id, "status": status}))
    if status != "done":
        error = catalogues.describe(ctx, catalogue_id).error
        raise CliError(f"catalogue {catalogue_id} {status}: {error}")
    return 0


def _create(args: argparse.Namespace) -> int:
    ctx = _context_with_pool()
    from app.services import catalogues

    try:
        row = catalogues.create(ctx, n=args.n, seed=args.seed,
                                constraints=args.constraints or ["ttc<3"], model=args.model,
                                method=args.sampler, score=not args.no_score,
                                chunk_size=args.chunk_size, wagner_scan=args.wagner_scan)
        print(f"catalogue {row.id}: {row.n} scenarios in {row.n_chunks} chunks",
              file=sys.stderr)
        return _run(ctx, row.id, not args.quiet)
    finally:
        ctx.close()


def _resume(args: argparse.Namespace) -> int:
    from app.jobs.joblock import JobBusy, check_free
    from app.settings import get_settings

    # a job another process runs is refused before the pool's workers start (their start
    # took seconds before the runner found the job's lock held); the runner still takes
    # the lock itself, and refuses the same way if another took it meanwhile
    try:
        check_free(Path(get_settings().data_dir).resolve(), args.id)
    except JobBusy as busy:
        raise _left_to_its_runner(args.id, busy) from None
    ctx = _context_with_pool(load_defaults=False)
    try:
        return _run(ctx, args.id, not args.quiet)
    finally:
        ctx.close()


#: what ``catalogue status`` prints first (issue 25 item 6: the 100 bootstrap replicates
#: of P(A) came before everything a user looks for)
STATUS_FIRST = ("id", "status", "progress", "scenarios_done", "n", "constraints", "classes",
                "support", "rates", "stage", "error")


def status_for_reading(info: dict[str, Any]) -> dict[str, Any]:
    """The catalogue status (``app.statuses.catalogue_status_plain``) in reading order
    (``STATUS_FIRST``, then the rest, P(A) last) with P(A)'s bootstrap replicates counted,
    not listed (``GET /catalogues/{id}`` has them)."""
    out = {k: info[k] for k in STATUS_FIRST if k in info}
    out.update({k: v for k, v in info.items() if k not in out and k != "p_region"})
    p_region = info.get("p_region")
    if isinstance(p_region, dict):
        p_region = dict(p_region)
        mi = p_region.get("model_interval")
        if isinstance(mi, dict) and "replicates" in mi:
            p_region["model_interval"] = {k: v for k, v in mi.items() if k != "replicates"}
        out["p_region"] = p_region
    return out


def _status(args: argparse.Namespace) -> int:
    from app.services import catalogues
    from app.statuses import catalogue_status_plain

    ctx = _context(load_defaults=False)
    try:
        info = catalogue_status_plain(catalogues.describe(ctx, args.id))
        print(json.dumps(status_for_reading(info), indent=2))
        p_region = info.get("p_region") or {}
        if p_region.get("mc_ci") and p_region.get("model_ci"):
            from sampler.rates import report_text  # both intervals, each with its reading

            print(report_text({"p_region": p_region, "rates": info.get("rates"),
                               "model_interval": p_region.get("model_interval")}),
                  file=sys.stderr)
    except LookupError as exc:
        raise _in_store(exc) from None
    finally:
        ctx.close()
    return 0


def _scenarios(args: argparse.Namespace) -> int:
    from app.services import catalogues

    items = []
    for text in args.filters:
        name, sep, value = text.partition("=")
        if not sep:
            raise CliError(f"--filter {text!r}: expected NAME=VALUE, e.g. btn_min=0.7")
        items.append((name.strip(), value.strip()))
    flt = catalogues.page_filter(items, args.classes, where="--filter")
    desc = catalogues.check_order(args.order_by, False if args.asc else None,
                                  where="--order-by")
    if args.limit < 1 or args.offset < 0:
        raise CliError("--limit must be >= 1 and --offset >= 0")
    ctx = _context(load_defaults=False)
    try:
        page = catalogues.page_scenarios(ctx, args.id, flt, args.offset, args.limit,
                                         order_by=args.order_by, desc=desc)
        for record in page.records:
            print(record.model_dump_json())
        print(json.dumps({"total": page.total, "offset": args.offset, "limit": args.limit}),
              file=sys.stderr)
    finally:
        ctx.close()
    return 0


def _list(args: argparse.Namespace) -> int:
    from app.services import catalogues

    ctx = _context(load_defaults=False)
    try:
        rows = [(r.id, r.status, str(r.n), str(r.seed),
                 "; ".join(r.spec.get("constraints", [])) or "(none)", r.model_id,
                 f"{r.created_at:%Y-%m-%d %H:%M}") for r in catalogues.list_catalogues(ctx)]
    finally:
        ctx.close()
    # a header and the constraints: two catalogues of the same n and seed looked alike
    head = ("id", "status", "n", "seed", "constraints", "model", "created (UTC)")
    print_columns([head, *rows], right=(2, 3))
    return 0


def print_columns(rows: list[tuple[str, ...]], right: tuple[int, ...] = ()) -> None:
    """Rows as aligned columns two blanks apart (``right``: columns aligned right)."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        cells = [c.rjust(w) if i in right else c.ljust(w)
                 for i, (c, w) in enumerate(zip(r, widths, strict=True))]
        print("  ".join(cells).rstrip())


def _export(args: argparse.Namespace) -> int:
    from app.services import catalogues

    out = Path(args.output)
    if not out.parent.is_dir():
        raise CliError(f"--out: directory {out.parent} does not exist")
    bar: Any = None

    def progress(done: int, n: int) -> None:
        nonlocal bar
        if args.quiet:
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=n, unit="scenario", desc=f"export {args.format}",
                       file=sys.stderr, leave=False)
        bar.update(done - bar.n)
        if done == n:
            bar.refresh()  # the last count shows even when it came within tqdm's interval

    ctx = _context(load_defaults=False)
    try:
        out = catalogues.export(ctx, args.id, args.format, out, mode=args.mode,
                                progress=progress)
    except LookupError as exc:
        raise _in_store(exc) from None
    finally:
        if bar is not None:
            bar.close()
        ctx.close()
    print(str(out))
    return 0
