"""The one place flighttest reaches under MAVSDK's asyncio wrapper (``VehicleLink.offboard_setters``):
if a MAVSDK release moves it, this fails here, not in the air."""

from __future__ import annotations

import inspect

from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.plugins.offboard import Offboard

from flighttest.flying.link import OFFBOARD_SETTERS


def test_offboard_async_wraps_a_synchronous_plugin_with_the_setters_the_streamer_calls():
    # OffboardAsync keeps the synchronous plugin as ``_plugin`` (an Offboard) ...
    assert "self._plugin = Offboard(" in inspect.getsource(OffboardAsync.__init__)
    # ... whose setters flighttest's streamer calls on the event loop
    for name in OFFBOARD_SETTERS:
        assert callable(getattr(Offboard, name, None)), name
