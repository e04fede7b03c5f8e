"""Numerics below the physics: the globalised semismooth Newton driver (:mod:`.newton`) and its
dense backend (:mod:`.nonsmooth`), Anderson mixing (:mod:`.anderson`) and PETSc helpers
(:mod:`.linalg`)."""
