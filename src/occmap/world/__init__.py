"""World-scale maps: the world cut into fixed, axis-aligned tiles in a global integer key space,
kept in a folder others can read, built out of core and in parallel on Dask, equal to the map one
process builds (issue 17)."""
