"""Generation, one stage for every model family: ``drivewm generate`` and ``drivewm rollout``.

- ``config.py``: :class:`GenerateConfig`, the one typed config (sampling, opt-in post-steps, rollouts);
- ``protocol.py`` / ``registry.py``: the :class:`Generator` protocol and the generators by model type;
- ``text2world.py`` / ``multiview.py``: the two families' generators; ``rollout.py``: multi-view rollouts;
- ``captions.py``: prompts into per-view captions; ``reproject.py``: the opt-in reproject post-step;
- ``writer.py``: samples -> clip shards, videos and contact sheets; ``commands.py``: the command line.
"""
