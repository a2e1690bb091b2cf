"""Closing rerun streams that rerun cannot close: slam.viz.stream.disconnect and slam.cli.entry.

rerun 0.41 can block for ever in ``RecordingStream.disconnect`` once its file writer died on a
failed write (a full disk); the fakes below block the same way, deterministically."""

from __future__ import annotations

import threading

import pytest

import slam.cli as cli
import slam.viz.stream as stream


class _Stuck:
    """A stream whose disconnect blocks until released (rerun's, after its writer died)."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.calls = 0

    def disconnect(self) -> None:
        self.calls += 1
        self.release.wait()


class _Failing:
    def disconnect(self) -> None:
        raise RuntimeError("Failed to write: No space left on device (os error 28)")


@pytest.fixture
def no_wedged(monkeypatch):
    monkeypatch.setattr(stream, "_WEDGED", [])


def test_a_disconnect_that_never_returns_is_given_up_and_remembered(no_wedged):
    stuck = _Stuck()
    try:
        assert stream.disconnect(stuck, wait=0.2) is False  # type: ignore[arg-type]
        assert stuck.calls == 1 and stream.wedged() and [stuck] == stream._WEDGED
    finally:
        stuck.release.set()  # let the daemon thread end


def test_a_disconnect_that_returns_or_fails(no_wedged):
    done = _Stuck()
    done.release.set()
    assert stream.disconnect(done, wait=5.0) is True  # type: ignore[arg-type]
    with pytest.raises(RuntimeError, match="No space left"):
        stream.disconnect(_Failing())  # type: ignore[arg-type]
    assert stream.disconnect(_Failing(), raising=False) is True  # type: ignore[arg-type]
    assert not stream.wedged()


def test_close_stream_of_a_failed_write_never_hangs(no_wedged, tmp_path):
    """The flush reports the failed write; the disconnect after it is bounded, and the error
    names the file (ENOSPC when its file system is full, else EIO)."""
    stuck = _Stuck()

    class Rec(_Stuck):
        def flush(self) -> None:
            raise RuntimeError("Failed to write")

    rec = Rec()
    rec.release = stuck.release
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(stream, "DISCONNECT_WAIT_S", 0.2)
            with pytest.raises(OSError) as info:
                stream.close_stream(rec, tmp_path / "r.rrd")  # type: ignore[arg-type]
        assert info.value.filename == str(tmp_path / "r.rrd")
        assert stream.wedged()
    finally:
        stuck.release.set()


@pytest.mark.parametrize("stuck", [True, False])
def test_the_command_ends_without_the_interpreters_clean_up_only_when_wedged(
    monkeypatch, capsys, stuck
):
    exits: list[tuple[str, int]] = []

    class Ended(Exception):
        pass

    def hard_exit(code: int) -> None:
        exits.append(("os._exit", code))
        raise Ended

    monkeypatch.setattr(cli, "main", lambda: 2)
    monkeypatch.setattr(cli.os, "_exit", hard_exit)
    monkeypatch.setattr(stream, "_WEDGED", [object()] if stuck else [])
    if stuck:
        with pytest.raises(Ended):
            cli.entry()
        assert exits == [("os._exit", 2)]
    else:
        with pytest.raises(SystemExit) as info:
            cli.entry()
        assert info.value.code == 2 and exits == []
