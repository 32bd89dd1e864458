"""LiveLink: commands given while the tracker process starts are sent once it runs."""

from types import SimpleNamespace

from game.live_link import LinkState, LiveLink


class FakeTracker:
    """What LiveLink uses of tracking.live.LiveTracker: start, status, ready, poll, commands."""

    def __init__(self) -> None:
        self.ready = False
        self.calls: list[tuple] = []

    def start(self, timeout_s, wait=False) -> None:
        pass

    def status(self):
        return SimpleNamespace(alive=self.ready, last_error="")

    def poll(self) -> list:
        return []

    def set_patient_input(self, value) -> None:
        self.calls.append(("set_patient_input", value))

    def set_motion(self, name) -> None:
        self.calls.append(("set_motion", name))

    def reidentify(self) -> None:
        self.calls.append(("reidentify",))


def test_commands_before_the_tracker_runs_are_sent_when_it_does_newest_of_each_kind():
    tracker = FakeTracker()
    link = LiveLink(lambda: tracker, clock=lambda: 0.0)
    link.start()
    link.set_patient_input("hand at A")
    link.set_patient_input("hand at B")  # replaces the first: only the newest input matters
    link.set_motion("reach")
    link.reidentify()
    link.tick()
    assert link.state is LinkState.STARTING and tracker.calls == []
    tracker.ready = True
    link.tick()
    assert link.state is LinkState.RUNNING
    assert sorted(tracker.calls) == sorted([("set_patient_input", "hand at B"), ("set_motion", "reach"), ("reidentify",)])
    link.tick()  # sent once
    assert len(tracker.calls) == 3
    link.set_motion("shoulder_flexion")  # running: sent at once
    assert tracker.calls[-1] == ("set_motion", "shoulder_flexion")
