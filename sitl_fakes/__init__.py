"""A fake PX4 quadcopter for tests and ground rehearsals: MAVLink 2 over UDP, rigid-body physics,
a PX4-like controller and a VRS/WBS disturbance model whose truth is set on the command line; with
``--autopilot ardupilot`` the same vehicle behaves as ArduCopter (``sitl_fakes.ardupilot_vehicle``).

Run it with ``python -m sitl_fakes --vehicle x500`` (or ``flighttest sim``); start it from Python or
pytest with :class:`sitl_fakes.launcher.FakeVehicle`. See ``sitl_fakes/README.md``.
"""
