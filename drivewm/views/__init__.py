"""View geometry shared by generation, transfer and eval: rays of a rig's pixels and tokens, the
flat-world warp of a first frame along a trajectory, blending where cameras overlap, reshading a
warped road, and tiling the views into one grid. Below every model package: it imports none."""
