"""One EnergyPlus process per episode behind a pair of named pipes: its configuration, lifecycle, the float-frame
protocol, the EnergyPlus-side program and its per-step bridge (Python and C), the episode's step table.

May import buildings (what to sense and actuate), io and errors only.
"""
