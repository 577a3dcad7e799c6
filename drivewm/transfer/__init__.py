"""Weather and time-of-day transfer of multi-view clips: the same drive, in snow.

- ``retarget.py``: the target condition and a clip's labels retold in it (tags, captions);
- ``data.py``: paired samples (same ``pair_id``, other condition) from the latent cache;
- ``model.py`` (+ ``config.py``, ``condition_encoder.py``): the Text2World DiT conditioned on the
  source clip's latents (zero-initialised patch projection) and the target weather / time of day;
- ``init.py``: start equal to the Text2World parent; ``train.py``: recipe + training task;
- ``sampling.py``: sampling from noise or from a noised clip; ``sdedit.py``: the SDEdit baseline;
- ``apply.py``: clips in, transferred clips out (``drivewm transfer``); ``metrics.py``: the
  benchmark's measures; ``commands.py``: the CLI. See README.md.

Nothing is imported here, so ``drivewm --help`` stays fast.
"""
