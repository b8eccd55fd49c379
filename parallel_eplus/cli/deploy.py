"""`parallel-eplus export` and `serve`: a trained policy as a controller file, and that file over HTTP."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_commands(sub) -> None:
    """The two subcommands, declared here so cli/parser.py gains one line."""
    ex = sub.add_parser("export", help="a trained policy or planner as ONNX with its contract controller.json")
    ex.add_argument("policy", type=Path, metavar="RUN_OR_MODEL",
                    help="a run folder, its model.zip or a checkpoint; a model-based run (or planner/): its planner")
    ex.add_argument("-o", "--out", type=Path, default=Path("controller"), help="folder to write (default controller)")
    ex.add_argument("--persistence", action="store_true",
                    help="planner: answer requests without a forecast, holding the outdoor reading (answers say so)")
    ex.add_argument("--fallback-spread-k", type=float, metavar="K",
                    help="planner: fall back when the model's members disagree by more than K about a zone along the "
                    "plan (default: 3 x the largest spread on the building's own days, at least 0.5 K)")
    ex.add_argument("--fallback-input-z", type=float, default=6.0, metavar="Z",
                    help="planner: fall back when a model input is more than Z standard deviations from its data")
    ex.add_argument("--record-days", type=int, metavar="N",
                    help="planner: days of its own controls recorded for the fallback (default: the run's, up to 365)")
    ex.add_argument("--workers", type=int, default=2, help="planner: EnergyPlus runs at once (own controls)")
    ex.set_defaults(func=cmd_export, needs="export")
    se = sub.add_parser("serve", help="serve an exported controller over HTTP: POST /act, GET /health, GET /contract")
    se.add_argument("controller", type=Path, metavar="DIR", help="a folder written by `export`")
    se.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0: all)")
    se.add_argument("--port", type=int, default=8000)
    se.add_argument("--token-file", type=Path, metavar="FILE",
                    help="a secret on its first line: every request must send Authorization: Bearer <it> "
                    "(required off loopback)")
    se.add_argument("--ssl-keyfile", type=Path, help="TLS: the server's private key (PEM), with --ssl-certfile")
    se.add_argument("--ssl-certfile", type=Path, help="TLS: the server's certificate chain (PEM)")
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

    path = export(args.policy, args.out, workers=args.workers, max_input_z=args.fallback_input_z,
                  max_spread_k=args.fallback_spread_k, persistence=args.persistence,
                  record_days=args.record_days)  # fmt: skip
    files = ", ".join(sorted(p.name for p in path.parent.iterdir() if p.suffix in (".onnx", ".npz", ".json")))
    print(f"written: {path.parent}/ ({files})")
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    try:
        from parallel_eplus.deploy.server import serve  # no torch: onnxruntime, FastAPI and the contract only
    except ImportError as e:
        raise _needs("serve", e) from None

    serve(args.controller, args.host, args.port, args.token_file, args.ssl_keyfile, args.ssl_certfile)
    return 0
