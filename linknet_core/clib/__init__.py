"""The native core's ctypes binding, a leaf: the compiled library (linknet_core/native/_linknet*, built from
linknet_core/native/src by setup.py), its struct mirrors, status codes and the LDL^T/AMD entry points. It imports
nothing of linknet_core but the tolerances, so every stage (the numpy reference's structure and dynamics, the errors'
texts, the native fast path) may use it without an import against the data flow."""
