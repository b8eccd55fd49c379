"""A building as data: its spec (TOML) resolved once into one object (sensors, actuators, bounds, reward, comfort),
its EnergyPlus model prepared for a run, the rule-based controller, weather files, and the `building init` /
`check` / `survey` tools that read a model through EnergyPlus's own listing.

The bottom layer: imports only io and errors.
"""
