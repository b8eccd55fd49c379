"""`parallel-eplus presets [NAME]`: the shipped presets, one line each, or one with every setting and its reason."""

from __future__ import annotations

import argparse

from parallel_eplus.presets.catalog import load_preset, names


def cmd_presets(args: argparse.Namespace) -> int:
    if args.name:
        print("\n".join(load_preset(args.name).describe()))
        return 0
    presets = [load_preset(n) for n in names()]
    width = max(len(p.name) for p in presets)
    print(f"{'PRESET':<{width}}  {'FOR':<10}  SUMMARY")
    for p in presets:
        print(f"{p.name:<{width}}  {p.kind:<10}  {p.summary}")
    print("\n`parallel-eplus presets NAME` shows one with every setting; `train --preset NAME` and "
          "`evaluate --preset NAME` use it (flags override it).")  # fmt: skip
    return 0
