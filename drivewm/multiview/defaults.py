"""Defaults of reprojected refinement (drivewm.multiview.reproject), apart so that the command line
reads them without importing torch."""

DEFAULT_SIGMA = 0.1
"""``--reproject`` of ``drivewm generate`` (multi-view models) and ``drivewm rollout`` when none is given
(their help texts and the benchmark's say it too; a test holds them to it), with the warp reshaded
(:data:`DEFAULT_RESHADE`). 0.3 was chosen first on validation prompts (never the benchmark's), closest
to the asked turns (studies/reproject_sigma.py); at 0.1 the samples keep more of the warp's geometry
(the TSE must-hold holds, 1.12x against 1.80x) and, reshaded, every must-hold of 0.3 still holds,
fog's adherence with them (docs/benchmark/shipped, 0.3's docs/benchmark/sigma03;
docs/quality-vs-compute.md, "Fog reads snow at --reproject 0.1"). Rollouts of held-out clips turn
the asked way in 12 of 12 either way."""

DEFAULT_RESHADE = True
"""``--reproject-reshade`` when neither it nor ``--no-reproject-reshade`` is given: on. Clear and snow
lose at most 0.13 dB of the warp's PSNR to it, fog gains 7.4 (studies/warp_haze.py), and without it
fog reads snow at :data:`DEFAULT_SIGMA`."""

DEFAULT_BLEND = True
"""``--reproject-blend`` of ``drivewm generate`` when neither it nor ``--no-reproject-blend`` is given:
the first pass's first frame blended where the rig's cameras overlap before it is reprojected
(drivewm.multiview.blend), so the views agree there. On the validation prompts of
studies/reproject_sigma.py the camera pairs that count towards CSE went from 28 % to 53 % (the
held-out clips' 50 %); on the benchmark from 19 % to 41 %, CSE from 1.55x to 1.19x the held-out
clips', pose success from 0.17 to 0.25, every must-hold that held still holding
(docs/benchmark/shipped against docs/benchmark/reshade01; docs/quality-vs-compute.md, "Cameras that
disagree where they overlap")."""

DEFAULT_STITCH = True
"""``--stitch`` of ``drivewm generate`` when neither it nor ``--no-stitch`` is given: every decoded
frame of a generated clip blended where the rig's cameras overlap, as the first frame is before the
reprojection (drivewm.multiview.blend.stitch_views). The refinement redraws each view's texture on
its own, so the overlaps of the later frames disagree again; stitched, they agree. On the benchmark
(docs/benchmark/shipped against docs/benchmark/unstitched) the camera pairs that count towards CSE
went from 39.6 % to 76.4 % (the held-out clips' 50 %), CSE from 1.20x to 0.56x the held-out clips',
TSE from 1.17x to 1.10x; adherence and the turns held, pose success read 0.16 against 0.20 over
three COLMAP seeds. The CSE figure holds by the stitch's construction, not by what the network
learned: stitching the held-out clips themselves lifts their pairs counted from 46 % to 72 %
(docs/quality-vs-compute.md, "Stitched: every frame blended where the cameras overlap")."""
