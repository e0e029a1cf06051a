"""Descent planners: planar minimum time (Table II), 3D helix, vertical baseline, probe reference.

Modules: ``ocp`` (multiple shooting + IPOPT), ``multistart`` (the multi-start → fine solve →
refinement skeleton both optimising planners share), ``cone`` (the VRS/WBS constraint), ``planar``,
``cases`` (Table II), ``helix`` (3D), ``vertical``, ``probe``, ``problems`` (each kind's problem from
plain options, as ``flighttest plan`` builds it), ``export`` (→ trajectory files), ``plot``.
"""
