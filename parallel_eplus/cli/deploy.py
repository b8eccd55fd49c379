"""`parallel-eplus export` and `serve`: a trained policy as a controller file, and that file over HTTP."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_commands(sub) -> None:
    """The two subcommands, declared here so cli/parser.py gains one line."""
    ex = sub.add_parser("export", help="a trained policy as controller.onnx and its contract controller.json")
    ex.add_argument("policy", type=Path, metavar="RUN_OR_MODEL", help="a run folder, its model.zip or a checkpoint")
    ex.add_argument("-o", "--out", type=Path, default=Path("controller"), help="folder to write (default controller)")
    ex.set_defaults(func=cmd_export, needs="export")
    se = sub.add_parser("serve", help="serve an exported controller over HTTP: POST /act, GET /health, GET /contract")
    se.add_argument("controller", type=Path, metavar="DIR", help="a folder written by `export`")
    se.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0: all)")
    se.add_argument("--port", type=int, default=8000)
    se.set_defaults(func=cmd_serve, needs="serve")  # not `train`: a plant room's install


def _needs(extra: str, error: ImportError) -> ValueError:
    return ValueError(f"{error.name} is not installed: pip install 'parallel-eplus[{extra}]' (scripts/setup.sh does)")


def cmd_export(args: argparse.Namespace) -> int:
    try:
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError as e:
        raise _needs("export", e) from None
    from parallel_eplus.deploy.export import export

    path = export(args.policy, args.out)
    print(f"written: {path.parent / 'controller.onnx'}, {path}")
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    try:
        from parallel_eplus.deploy.server import serve  # no torch: onnxruntime, FastAPI and the contract only
    except ImportError as e:
        raise _needs("serve", e) from None

    serve(args.controller, args.host, args.port)
    return 0
