"""The independent check: the tension system derived symbolically with casadi (derivation), compared with
the numeric one (``linknet check``), and generated as C (codegen: the casadi right-hand side kernel)."""
from linknet_core.symbolic.derivation import SymbolicTensionSystem, sign_pattern

__all__ = ["SymbolicTensionSystem", "sign_pattern"]
