"""The mesh wing: the Mesh container, reading and checking mesh files (gmsh checks included), regions
and groups, generated bars, shells surfaces and solid balls, topology changes of the mesh itself,
refinement (simplex bisection, hexahedral 1:8, uniform levels) and point probes. Below: base."""
