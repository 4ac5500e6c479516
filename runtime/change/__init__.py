"""The change wing: what changes a model during a run (adaptive law switches and refinement, cuts,
removals, tearing). Below: base ... model."""
