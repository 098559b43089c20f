"""Physical simulation of a surface mesh: tetrahedralization, an XPBD solver and surface embedding."""
