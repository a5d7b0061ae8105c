"""Progress bars: live on a terminal, plain lines in a log file, silent for short work."""

from __future__ import annotations

import io
import time

import pytest

from sc2data.ground import progress


class _Log(io.StringIO):
    def isatty(self) -> bool:
        return False


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _run(bar: object, steps: int, pause: float) -> None:
    with bar as b:  # type: ignore[attr-defined]
        for _ in range(steps):
            time.sleep(pause)
            b.update(10)


def test_a_log_file_gets_whole_lines_once_work_lasts(monkeypatch: pytest.MonkeyPatch) -> None:
    log = _Log()
    monkeypatch.setattr("sys.stderr", log)
    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.05)
    _run(progress.bar(100, desc="rollout", unit="step", show=None), 10, 0.02)
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and len(lines) >= 2
    assert all(line.startswith("rollout:") for line in lines)
    assert "100/100" in lines[-1]


def test_short_work_in_a_log_file_prints_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    log = _Log()
    monkeypatch.setattr("sys.stderr", log)
    _run(progress.bar(100, desc="label", unit="stack", show=None), 3, 0.0)
    assert log.getvalue() == ""


@pytest.mark.parametrize("show,shown", [(None, True), (True, True), (False, False)])
def test_a_terminal_gets_a_live_bar_unless_turned_off(monkeypatch: pytest.MonkeyPatch,
                                                      show: bool | None, shown: bool) -> None:
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    _run(progress.bar(100, desc="pack", unit="stack", show=show), 3, 0.0)
    assert ("pack:" in term.getvalue()) is shown
    assert ("\r" in term.getvalue()) is shown
