"""Node-to-node frictional contact: contact pairs and the per-pair nonsmooth laws.

Submodules
----------
laws
    The pair laws H_i(w_i, z_i) = 0 (polar seed form and Cartesian Alart--Curnier form) as
    numba kernels vectorised over pairs, with their generalized Jacobians.
"""
