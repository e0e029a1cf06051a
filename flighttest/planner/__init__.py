"""Descent planners: planar minimum time (Table II), 3D helix, vertical baseline, probe reference.

Modules: ``ocp`` (multiple shooting + IPOPT), ``cone`` (the VRS/WBS constraint), ``planar``,
``cases`` (Table II), ``helix`` (3D), ``vertical``, ``probe``, ``export`` (→ trajectory files), ``plot``.
"""
