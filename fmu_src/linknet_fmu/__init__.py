"""Support code that travels inside every linknet FMU (next to the slave script).

It holds no physics: `layout` maps a scene onto FMI variables (names, value references,
units, dependencies) and is shared by the slave at run time and by build_fmu.py at build
time, so the model description and the behaviour cannot drift apart.
"""
