"""Multi-view post-training: a Text2World DiT extended (not forked) to all cameras of any rig, with
camera (Plucker-ray) and ego-trajectory conditioning, Video2World rollouts, and the CLI
(``drivewm posttrain``, ``drivewm generate`` for multiview folders, ``drivewm rollout``).

Heavy modules are imported where used; see drivewm.multiview.model for the model itself.
"""
