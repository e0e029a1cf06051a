"""The field day: probe → identify → plan → fly the vertical baseline and the helix → report.

A campaign lives in one folder; each step reads what earlier steps wrote there and records what it
wrote in ``campaign.json``, so an interrupted campaign resumes where it stopped and any step can be
run again alone::

    DIR/campaign.json          vehicle, and per step: status, elapsed time, outputs
    DIR/config/*.toml          the missions' configs for this campaign (edit, then re-run a step)
    DIR/flights/<ts>-<name>/   one flight log folder per flight (docs/CONTRACTS.md)
    DIR/identify.json          the probe's VRS onset
    DIR/vehicles/NAME.toml     the profile with the identified w_allow (the user's profile is untouched)
    DIR/plans/{vertical,helix}.{csv,json}   the planned descents (trajectory files)
    DIR/report/                summary.md, summary.json, compare.csv, report.md and the PNG figures
    DIR/sim/                   with --sim: the fake vehicle's ground-truth logs

``state`` holds the folder and its record (the step statuses: ``StepStatus``), ``steps`` what each step
does, ``run`` the loop that runs and resumes them (``Campaign``: the fake vehicle, Ctrl-C, the record kept
whatever ends a step), ``summary`` and ``figures`` the report; the command (arguments, the console, the
prompts, the printed summary) is ``flighttest.cli.campaign``.
"""
