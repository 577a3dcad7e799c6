"""Text2World diffusion: separate, narrow pieces.

- ``dit.py`` (+ ``dit_config.py``, ``blocks.py``, ``rope.py``): the backbone F, a DiT over
  (latent frame, row, column) patches; sub-layers per block are configurable for multi-view.
- ``denoiser.py``: EDM preconditioning D = c_skip x + c_out F(c_in x; c_noise), the loss, CFG
  text dropout and Video2World conditioning.
- ``samplers.py``: EDM Euler/Heun with one signature, Karras sigmas, classifier-free guidance.
- ``data.py``: samples from the latent cache; ``pretrain.py``: recipe + training task;
  ``text2world.py``: the model folder; ``generate.py``: prompts -> clips; ``commands.py``: CLI.

Nothing is imported here, so ``drivewm --help`` (which imports ``commands``) stays fast.
"""
