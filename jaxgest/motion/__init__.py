"""Motion data: BVH I/O, rotations, skeletons, kinematics, datasets and the built-in synthetic data."""
