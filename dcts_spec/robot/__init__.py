"""Robot models: built-in robots, URDF loading, extra frames and merged limits."""
