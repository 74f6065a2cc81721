"""Command line: ``python -m dpht <command>`` (also installed as ``dpht``).

Commands:
  verify [NAME ...]   run the verification cases (``--list`` to list them)
  stage NAME          run one workflow stage (called by the Snakemake rules)
"""

from __future__ import annotations

import argparse
import sys

from .errors import DPHTError


def _verify(args) -> int:
    from . import verify

    if args.list:
        for name, case in verify.cases().items():
            print(f"{name:<34s} {case.description}")
        return 0
    try:
        outcomes = verify.run(args.names)
    except KeyError as err:
        raise DPHTError(str(err.args[0])) from None
    failed = [o.name for o in outcomes if not o.passed]
    print(f"{len(outcomes) - len(failed)}/{len(outcomes)} passed" + (f"; FAILED: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


def _stage(args) -> int:
    from . import stages

    return stages.run(args.name, args.spec, args.io, args.log)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m dpht", description=__doc__.split("\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)

    p = commands.add_parser("verify", help="run verification cases against exact or reference solutions")
    p.add_argument("names", nargs="*", help="cases to run (default: all)")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    p.set_defaults(func=_verify)

    p = commands.add_parser("stage", help="run one workflow stage (used by the Snakemake rules)")
    p.add_argument("name")
    p.add_argument("--spec", required=True, help="stage parameters as JSON")
    p.add_argument("--io", required=True, help="input/output paths and threads as JSON")
    p.add_argument("--log", help="also write progress and errors to this file")
    p.set_defaults(func=_stage)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except DPHTError as err:
        print(f"dpht: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
