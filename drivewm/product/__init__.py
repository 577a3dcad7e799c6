"""The product built on the stages: the recipe that trains the shipped models, their release, and the quickstart.

``worldmodel`` (``drivewm worldmodel train|figures|export``) runs the stages as one resumable recipe;
``figures`` turns its evaluation into the must-hold figures; ``release`` exports a run's model
folders as the shipped weights (with ``model_card``); ``quickstart`` (``drivewm quickstart``) runs
the fleet fine-tuning story through the public commands and ``report`` writes its HTML report.
Nothing below this package imports it: the stages and the CLI's argparse types find the shipped
weights through drivewm.model_folders.
"""
