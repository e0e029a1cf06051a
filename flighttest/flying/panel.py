"""The live panel while flying (rich): phase, altitude, descent rate, the wind the guard judges with, w and u,
guard margin, setpoint jitter, link health. Refreshed a few times a second from the runner's state; drawing never blocks
the guard (rich's Live redraws from its own thread)."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

from rich.live import Live
from rich.table import Table

from flighttest.flying.wind import WindEstimate


def _f(v: float, fmt: str = ".2f", unit: str = "") -> str:
    return "—" if v is None or not math.isfinite(v) else f"{v:{fmt}}{unit}"


def wind_rows(wind: WindEstimate) -> list[tuple[str, str]]:
    """The wind as an operator reads it: its speed, the direction it blows from (as a windsock and ArduCopter's
    ``SIM_WIND_DIR`` give it), its 1 σ and source; and the updraft the guard allows for the gusts."""
    speed = math.hypot(*wind.ned_mps[:2])
    from_deg = math.degrees(math.atan2(-wind.ned_mps[1], -wind.ned_mps[0])) % 360.0
    where = f" from {from_deg:03.0f}°" if speed >= 0.05 else ""
    return [("wind", f"{speed:.1f} ± {wind.sd_mps:.2f} m/s{where} ({wind.source})"),
            ("updraft allowed", f"{wind.updraft_mps:.2f} m/s (gusts 1 σ {wind.gust_sd_mps:.2f} m/s)")]


class LivePanel:
    def __init__(self, runner, console) -> None:
        self.runner = runner
        self.live = Live(self.render(), console=console, refresh_per_second=5, transient=False,
                         get_renderable=self.render)  # fmt: skip

    def render(self) -> Table:
        r = self.runner
        st = r.link.state if r.link is not None else None
        d = r.last_decision
        t = Table(title=f"flighttest fly — {r.mission_name}", show_header=False)
        # fixed widths: the frame must not jump as the numbers change length
        t.add_column("what", style="bold", width=16, no_wrap=True)
        t.add_column("value", width=52, no_wrap=True, overflow="ellipsis")
        abort = f"  [red]ABORT {r.ladder.rung.name}: {r.ladder.reason}[/]" if r.ladder.active else ""
        t.add_row("phase", r.phase + abort)
        if st is not None:
            t.add_row("mode / armed", f"{st.flight_mode} / {st.armed}")
            t.add_row("altitude", _f(st.alt_m, ".2f", " m"))
            t.add_row("descent rate", _f(st.vd_mps, "+.2f", " m/s"))
            now = r.now()  # the runner's clock, which stamped the samples (time.monotonic in flight)
            age = now - st.t_posvel if st.t_posvel else math.nan
            rate = st.rate_hz("posvel", now)
            up = "up" if st.connected else "[red]DOWN[/]"
            t.add_row("link", f"{up}, posvel {rate:.0f} Hz, last {_f(age * 1000, '.0f', ' ms')}")
            for row in wind_rows(r.watch.wind()):
                t.add_row(*row)
        if d is not None:
            colour = "green" if d.margin_mps >= 0 else "red"
            t.add_row("w / u", f"{_f(d.w_mps)} / {_f(d.u_mps)} m/s")
            t.add_row("guard margin", f"[{colour}]{_f(d.margin_mps)}[/] m/s (predicted {_f(d.predicted_margin_mps)})")
            t.add_row("guard verdict", d.verdict)
        j = r.streamer.jitter() if r.streamer is not None else None
        if j and j["n"]:
            t.add_row("setpoint jitter", f"p99 {j['p99_ms']:.1f} ms, {j['rate_hz']:.1f} Hz")
        return t

    def __enter__(self) -> LivePanel:
        self.live.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.live.__exit__(*exc)

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """Stop redrawing (for the go/no-go prompt: a redraw would overwrite the operator's answer)."""
        self.live.stop()
        try:
            yield
        finally:
            self.live.start()
