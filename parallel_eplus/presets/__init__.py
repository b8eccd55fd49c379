"""Named, versioned settings that earned their place (`train --preset NAME`, `evaluate --preset NAME`,
`parallel-eplus presets`): TOML files shipped in this folder, read by `catalog.py`. It imports nothing of the package's
own: the command line turns a preset into the options' defaults, which flags then override.
"""
