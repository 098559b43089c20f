"""Loopable cyclic animation from elliptic PDE surfaces: a body as a chain of PDE patches between
cross-section curves, its spine A0(u) driven by a periodic swim wave, and the motion carried to the mesh."""
