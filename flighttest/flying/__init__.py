"""Flying a mission: the MAVLink link (``link``) and its ``.tlog`` recorder (``tlog_recorder``), the
setpoint streamer and what it sends an autopilot (``streamer``, ``feedforward``), the guard and its
abort ladder (``guard``), the preflight (``preflight``), the mission runner (``runner``) with its
settling rule (``settling``) and collector control (``pauses``), the flight log writer
(``log_writer``), the live panel (``panel``), and the missions' configs and scripts
(``missions_config``, ``plan_config``, ``mission_scripts``)."""
