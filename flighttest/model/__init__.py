"""The vehicle and its air: the VRS/WBS model and the guard region (``aero``), frames and blade-frame
velocity (``frames``), vehicle profiles (``profiles``), trajectory files (``trajectory``) and the
velocity-space chart (``chart``). Pure numpy; no I/O beyond reading and writing files."""
