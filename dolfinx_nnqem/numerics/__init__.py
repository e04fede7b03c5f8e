"""Numerics below the physics: the globalised semismooth Newton driver (:mod:`.newton`), its dense
backend (:mod:`.nonsmooth`) and PETSc helpers (:mod:`.linalg`)."""
