"""`parallel-eplus export` and `serve`: a trained policy as a controller file, and that file over HTTP."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_commands(sub) -> None:
    """The two subcommands, declared here so cli/parser.py gains one line."""
    ex = sub.add_parser("export", help="a trained policy or planner as ONNX with its contract controller.json")
    ex.add_argument(
        "policy",
        type=Path,
        metavar="RUN_OR_MODEL",
        help="a run folder, its model.zip or a checkpoint; a model-based run (or planner/): its planner",
    )
    ex.add_argument("-o", "--out", type=Path, default=Path("controller"), help="folder to write (default controller)")
    ex.add_argument(
        "--persistence",
        action="store_true",
        help="planner: answer requests without a forecast, holding the outdoor reading (answers say so)",
    )
    ex.add_argument(
        "--fallback-spread-k",
        type=float,
        metavar="K",
        help="planner: fall back when the model's members disagree by more than K about a zone along the "
        "plan (default: 3 x the largest spread on the building's own days, at least 0.5 K)",
    )
    ex.add_argument(
        "--fallback-input-z",
        type=float,
        default=6.0,
        metavar="Z",
        help="planner: fall back when a model input is more than Z standard deviations from its data",
    )
    ex.add_argument("--record-days", type=int, metavar="N",
                    help="planner: days of its own controls recorded for the fallback (default: 365, whatever the "
                    "run trained on)")  # fmt: skip
    ex.add_argument("--workers", type=int, default=2, help="planner: EnergyPlus runs at once (own controls)")
    ex.add_argument(
        "--planner-options",
        metavar="NAME=VALUE,...",
        help="planner: settings overriding its saved ones, as `evaluate --planner` (e.g. band_thermostats=baseline)",
    )
    ex.add_argument("--quiet", action="store_true", help="no progress bar (a log or CI's output stays readable)")
    ex.set_defaults(func=cmd_export, needs="export")
    se = sub.add_parser("serve", help="serve an exported controller over HTTP: POST /act, GET /health, GET /contract")
    se.add_argument("controller", type=Path, metavar="DIR", help="a folder written by `export`")
    se.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0: all)")
    se.add_argument("--port", type=int, default=8000)
    se.add_argument(
        "--token-file",
        type=Path,
        metavar="FILE",
        help="a secret on its first line: every request must send Authorization: Bearer <it> (required off loopback)",
    )
    se.add_argument("--ssl-keyfile", type=Path, help="TLS: the server's private key (PEM), with --ssl-certfile")
    se.add_argument("--ssl-certfile", type=Path, help="TLS: the server's certificate chain (PEM)")
    bn = se.add_argument_group("BACnet supervisor (docs/bacnet.md; needs the [bacnet] extra)")
    bn.add_argument("--bacnet", metavar="ADDRESS", help="supervise the BACnet/IP device at host[:port] instead of "
                    "serving HTTP: read its points, write the setpoints at --priority every control step")  # fmt: skip
    bn.add_argument("--point-map", type=Path, default=Path("points.toml"),
                    help="the device's points (TOML; `simulate --bacnet` writes one; default points.toml)")  # fmt: skip
    bn.add_argument("--priority", type=int, default=8, help="command priority, 8-16 (default 8; 1-7 refused)")
    bn.add_argument("--local", metavar="ADDRESS", help="this supervisor's own host[/mask][:port] (default: the "
                    "device's host, its port + 1)")  # fmt: skip
    bn.add_argument("--device-id", type=int, default=598, help="this supervisor's BACnet device instance")
    bn.add_argument("--bbmd", metavar="HOST:PORT", help="register as a foreign device with this BBMD")
    bn.add_argument("--bbmd-ttl", type=int, default=900, help="foreign device registration lifetime, s")
    bn.add_argument("--step-seconds", type=float, help="a device without a `step` point (a real one): act every this "
                    "many seconds (default: the map's control_step_s)")  # fmt: skip
    bn.add_argument("--no-advance", dest="advance", action="store_false",
                    help="on a lockstep device, leave `advance` to another client (a co-simulation clock)",
                    )  # fmt: skip
    se.set_defaults(func=cmd_serve, needs="serve")  # not `train`: a plant room's install


def _needs(extra: str, error: ImportError) -> ValueError:
    return ValueError(f"{error.name} is not installed: pip install 'parallel-eplus[{extra}]' (scripts/setup.sh does)")


def cmd_export(args: argparse.Namespace) -> int:
    try:
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError as e:
        raise _needs("export", e) from None
    from parallel_eplus.deploy.export.policy import export

    path = export(args.policy, args.out, workers=args.workers, max_input_z=args.fallback_input_z,
                  max_spread_k=args.fallback_spread_k, persistence=args.persistence,
                  record_days=args.record_days, options=args.planner_options, progress=not args.quiet)  # fmt: skip
    files = ", ".join(sorted(p.name for p in path.parent.iterdir() if p.suffix in (".onnx", ".npz", ".json")))
    print(f"written: {path.parent}/ ({files})")
    return 0


def needs_bacnet() -> None:
    from parallel_eplus.cli import extras

    if (absent := extras.missing("bacnet")) is not None:
        raise ValueError(extras.install_hint(absent, "bacnet"))


def cmd_serve(args: argparse.Namespace) -> int:
    if args.bacnet:
        needs_bacnet()
        from parallel_eplus.deploy.bacnet.supervisor import SupervisorConfig, supervise

        return supervise(SupervisorConfig(
            args.controller, args.bacnet, args.point_map, args.priority, args.local, args.device_id, args.bbmd,
            args.bbmd_ttl, advance=args.advance, step_seconds=args.step_seconds,
        ))  # fmt: skip
    try:
        from parallel_eplus.deploy.serve.server import serve  # no torch: onnxruntime, FastAPI and the contract only
    except ImportError as e:
        raise _needs("serve", e) from None

    serve(args.controller, args.host, args.port, args.token_file, args.ssl_keyfile, args.ssl_certfile)
    return 0
