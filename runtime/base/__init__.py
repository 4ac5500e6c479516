"""The base wing: errors and exit codes, paths, threads, the kernel cache folder, atomic file writes,
dofs per node and random test elements. It imports no other wing."""
