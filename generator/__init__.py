"""The symbolic generator: element -> energy -> derivatives -> constants -> fragments -> code.

Stages, each a module that takes plain data and returns plain data:
  elements, quadrature   reference shapes, shape functions, rules
  kinematics             deformation gradient F at a point from shape gradients
  derivatives            W(F), P = dW/dF, A = d2W/dF2 of a law, as sympy
  constants              rest-geometry kernel (J^-1, det J) and hoisting of
                         parameter-only subexpressions into per-element constants
  fragments              common-subexpression elimination into straight-line code
  ir                     KernelIR (frozen): everything a backend needs, language neutral
  kernel_body            the algorithm of every kernel as a statement tree (loops as data)
  (then ../backends/     one folder per language renders the IR: printer, templates, loader)
  catalogue, pipeline    what exists, and writing it to disk deterministically
"""
GENERATOR_VERSION = "0.1.0"
