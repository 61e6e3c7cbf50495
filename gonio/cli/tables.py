"""``gonio tables``: build, inspect and clear the tables of the tabulated models and rendered surfaces.

``gonio tables build [NAME ...]`` evaluates the exact model on the table grid (minutes on
a few cores) and writes the table to the user cache, or to ``--out``;
``gonio tables build surface:kind=...`` renders the table of a surface sample into the
cache (what its first use as an emulated sample would do, docs/surfaces.md);
``gonio tables info`` says which table each tabulated model would read and lists the
rendered surface tables in the cache;
``gonio tables clear`` deletes the tables ``gonio tables build`` wrote into the user cache
(recognised by name and by a signature inside the file) and lists every other file there,
which it keeps (never the tables shipped with gonio, never a user's own files).
"""
from __future__ import annotations

import argparse
import sys
import time

from . import CLIError


def check_output_file(output: str) -> None:
    """Refuse a ``tables build --out`` that would overwrite something gonio did not write.

    Parameters
    ----------
    output : str
        The ``--out`` argument.

    Raises
    ------
    CLIError
        For an empty name, a folder, a device or special file, or an existing file that
        is not a table written by gonio's builder.
    """
    from pathlib import Path

    from gonio.models.tabulated import store

    if not output.strip():
        raise CLIError(f"--out {output!r}: expected the name of a .npz file to write")
    path = Path(output)
    if path.is_dir():
        raise CLIError(f"--out {output}: is a folder; expected the name of a .npz file to write")
    if path.exists() and not path.is_file():
        raise CLIError(f"--out {output}: is a device or special file; expected the name of a .npz file to write")
    if path.exists() and not store.written_by_builder(path):
        raise CLIError(f"--out {output}: the file exists and is not a table written by 'gonio tables build' "
                       "(gonio never overwrites files it did not write); choose another name")


def _build_surface(spec: str, args: argparse.Namespace) -> None:
    """Render (or find) the table of the surface sample ``spec`` in the user cache."""
    from .samples import SURFACE_PREFIX, parse_sample_spec

    if args.output is not None or args.grid:
        raise CLIError(f"{spec}: --out and --grid apply to model tables; a surface table is cached under "
                       "its key (docs/surfaces.md)")
    sample = parse_sample_spec(spec)
    if args.workers is not None:
        sample.brdf.workers = args.workers
    if args.quiet:
        sample.brdf.progress = None
    sample.prepare()
    state = "rendered" if sample.brdf.rendered else "already cached"
    print(f"{state}: {sample.brdf.path} ({SURFACE_PREFIX}{sample.brdf.spec.text()})")


def _run_build(args: argparse.Namespace) -> int:
    from gonio.models import tabulated

    from .samples import SURFACE_PREFIX

    surfaces = [name for name in args.name if name.lower().startswith(SURFACE_PREFIX)]
    for spec in surfaces:
        _build_surface(spec, args)
    if surfaces and len(surfaces) == len(args.name):
        return 0
    names = [name for name in args.name if name not in surfaces] or sorted(tabulated.TABLES)
    unknown = [name for name in names if name not in tabulated.TABLES]
    if unknown:
        raise CLIError(f"unknown table {unknown[0]!r}; known tables: {sorted(tabulated.TABLES)}")
    if args.output is not None:
        if len(names) != 1:
            raise CLIError("--out needs exactly one table name")
        check_output_file(args.output)
    options = {}
    if args.grid:
        from gonio.models.tabulated.oren_nayar_table import OrenNayarGrid

        try:
            options["grid"] = OrenNayarGrid(*(int(n) for n in args.grid.split(",")))
        except (TypeError, ValueError):
            raise CLIError(f"--grid {args.grid!r}: expected four node counts 'y,zeta,t,s', e.g. 45,12,16,28") from None
    start = time.perf_counter()

    def progress(done: int, total: int) -> None:
        print(f"\r  {done}/{total} roughness nodes, {time.perf_counter() - start:.0f} s", end="", file=sys.stderr, flush=True)

    for name in names:
        detail = f" (rtol {args.rtol:g})" if name == "oren-nayar" else ""
        print(f"building table {name!r}{detail}", file=sys.stderr)
        path = tabulated.build(name, output=args.output, rtol=args.rtol, workers=args.workers,
                               progress=None if args.quiet else progress, **options)
        print("", file=sys.stderr)
        print(f"wrote {path}")
    return 0


def _run_info(args: argparse.Namespace) -> int:
    from gonio.models import tabulated
    from gonio.models.tabulated import store

    print(f"user cache: {store.cache_dir()}")
    print(f"shipped:    {store.PACKAGE_DIR}")
    for name in args.name or sorted(tabulated.TABLES):
        info = tabulated.describe(name)
        print(f"{name}: model {info['model']} (values of {info['reference']})")
        if info["path"] is None:
            print(f"    no table found; build it with 'gonio tables build {name}'")
            continue
        origin = "shipped" if info["shipped"] else "user cache"
        print(f"    {info['path']} ({origin}, {info['bytes'] / 1e6:.1f} MB)")
        print(f"    grid {' x '.join(map(str, info['shape']))} = {info['nodes']} nodes, exact rtol {info['rtol']:g}, "
              f"built in {info['build_seconds']:.0f} s")
    if not args.name:
        _print_surface_tables()
    return 0


def _print_surface_tables() -> None:
    """The rendered surface tables in the user cache (docs/surfaces.md)."""
    from gonio.surfaces.table import cached_tables

    found = cached_tables()
    print(f"rendered surfaces (gonio.surfaces): {len(found)} table{'s' if len(found) != 1 else ''} in the user cache")
    for entry in found:
        print(f"    {entry['path'].name}: surface:{entry['spec']}")
        error = (f"Monte Carlo error per node median {entry['median_error']:.3%} (max {entry['max_error']:.3%})"
                 if entry["max_error"] > 0.0 else "every order exact, nothing sampled")
        print(f"        {entry['nodes']} nodes, {error}, {entry['bytes'] / 1e3:.0f} kB, "
              f"rendered in {entry['build_seconds']:.0f} s")


def _run_clear(args: argparse.Namespace) -> int:
    from gonio.models import tabulated
    from gonio.models.tabulated import store

    removed = store.clear_cache()
    tabulated._forget_loaded()
    _, kept = store.cache_contents()
    for path in removed:
        print(f"removed {path}")
    if not removed:
        print(f"no table built by gonio in {store.cache_dir()}")
    for path in kept:
        print(f"kept {path} (not a table written by 'gonio tables build')")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio tables build|info|clear``."""
    parser = subparsers.add_parser("tables", help="build, inspect or clear the tables of tabulated models")
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    build = actions.add_parser("build", help="compute a table with the exact model (slow: minutes)")
    build.add_argument("name", nargs="*", help="table names (default: all) or surface sample specs "
                                                "(surface:kind=...,...)")
    build.add_argument("--out", "--output", dest="output",
                       help="file to write instead of the user cache (--output: the same, its older name)")
    build.add_argument("--rtol", type=float, default=1e-5, help="accuracy of oren-nayar-exact at the nodes")
    build.add_argument("--workers", type=int, default=None,
                       help="processes (threads for a surface) (default: all CPUs)")
    build.add_argument("--grid", help="node counts 'y,zeta,t,s' (default: the shipped grid)")
    build.add_argument("--quiet", action="store_true", help="no progress output")
    build.set_defaults(func=_run_build)
    info = actions.add_parser("info", help="which table each tabulated model reads; the rendered surface tables")
    info.add_argument("name", nargs="*", help="table names (default: all)")
    info.set_defaults(func=_run_info)
    clear = actions.add_parser("clear", help="delete the tables gonio built in the user cache (other files are kept)")
    clear.set_defaults(func=_run_clear)
    parser.set_defaults(func=lambda args: (parser.print_help(), 0)[1])
