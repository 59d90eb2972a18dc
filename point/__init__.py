"""The material point of any constitutive law of the plane: the contract a law implements
(``point.contract``), the benchmark law with exact bifurcation criteria (non-associated
Drucker-Prager, ``point.drucker_prager``, ``point.closed_forms``) and the analysis written once
for every law."""
from .contract import (Material, MaterialError, ParamError, Rows, register, material_of,
                       material_named, check_tangent)

__all__ = ["Material", "MaterialError", "ParamError", "Rows", "register", "material_of",
           "material_named", "check_tangent"]
