"""``serenity sweep``: a sweep file's frames, references and comparisons on Dask (see :mod:`serenity.sweep`).

    serenity sweep examples/sweep_day.toml [--scheduler ADDRESS] [--workers N] [--out DIR]

Needs the ``eval`` extra (Dask, Mitsuba 3, FLIP); without it the command says so in one line.
Exit status 0 when every task is done, 1 when some failed (their errors are in the manifest).
"""

from __future__ import annotations


def register(subparsers) -> None:
    s = subparsers.add_parser("sweep", help="render a sweep file's frames, references and comparisons on Dask "
                                            "(resumable; contact sheet, time-of-day GIF, metrics CSV/JSON; "
                                            "needs serenity[eval])")
    s.add_argument("spec", help="sweep file (TOML; see examples/sweep_day.toml)")
    s.add_argument("--out", help="results directory (default: [sweep].out, else serenity_out/sweep/<name>)")
    s.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 "
                                       "(default: an embedded LocalCluster)")
    s.add_argument("--workers", type=int, help="worker processes of the embedded cluster (default: one per core)")
    s.add_argument("--cache", help="reference cache directory shared by the workers (default: SERENITY_CACHE "
                                   "or ~/.cache/serenity/reference)")
    s.add_argument("--retry-errors", action="store_true", help="run again the tasks that failed last time")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    s.set_defaults(func=run)


def run(args) -> int:
    from serenity.sweep import load_spec, run_sweep

    spec = load_spec(args.spec)
    result = run_sweep(spec, args.out, scheduler=args.scheduler, workers=args.workers, cache=args.cache,
                       retry_errors=args.retry_errors, progress=not args.quiet)
    return 1 if result.failed else 0
