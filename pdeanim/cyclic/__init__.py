"""Loopable cyclic animation: swim cycles from elliptic PDE surfaces (a body as a chain of PDE patches between
cross-section curves, its spine A0(u) driven by a periodic swim wave, the motion carried to the mesh), and
locomotion cycles of skinned legged characters from their skeleton alone (Eq. 9-10 per foot, leg IK)."""
