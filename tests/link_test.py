"""The host's telemetry link when the other end goes away, and a session over a port
waiting for the board to be armed."""

import os

import pytest

from heliquad.host.errors import InputError
from heliquad.host.link import TelemetryLink


def test_a_send_on_a_port_that_went_away_is_the_link_lost():
    # A board unplugged (here: the pty's other end closed) under a heartbeat, a command or a
    # stop: one error the tools already say in one line, not pyserial's exception. (A read
    # cannot tell a port gone from no data, VMIN = 0: the sessions' sample timeout sees it.)
    main, side = os.openpty()
    link = TelemetryLink(os.ttyname(side))
    os.close(side)
    try:
        link.heartbeat()                       # reaches the open pty
        os.close(main)
        for send in (link.heartbeat, link.stop_excitation, lambda: link.arm(False)):
            with pytest.raises(InputError, match="^telemetry link lost: "):
                send()
    finally:
        link.close()


class FakeBoard:
    """The board's end of a pty: HQ_SYSID_SAMPLEs written on demand, armed or not."""

    def __init__(self):
        from heliquad.sim.dialect import dialect

        self.main, side = os.openpty()
        self.port = os.ttyname(side)
        self.side = side
        self.mav = dialect().MAVLink(None, srcSystem=1, srcComponent=1)
        self.seq = 0

    def send_samples(self, n, armed):
        for _ in range(n):
            self.seq += 1
            msg = self.mav.hq_sysid_sample_encode(self.seq * 5000, self.seq, 0, 0, 0, int(armed),
                                                  0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, [0.4] * 5, 0)
            os.write(self.main, msg.pack(self.mav))

    def close(self):
        os.close(self.main)
        os.close(self.side)


@pytest.fixture
def board_session(tmp_path):
    from heliquad.host.session import PortSession

    board = FakeBoard()
    session = PortSession(board.port, str(tmp_path / "s.tlog"), poll_s=0.0)
    yield board, session
    session.close()
    board.close()


def test_a_sweep_over_a_port_waits_for_the_pilot_to_arm(board_session):
    # An excitation sent before the board is armed would be refused: the session waits for
    # an armed sample and says once that it is waiting; here the pilot arms when it does.
    board, session = board_session
    board.send_samples(3, armed=False)
    said = []

    def progress(text):
        said.append(text)
        board.send_samples(2, armed=True)

    session.hover(progress)
    assert said == ["waiting for the board to be armed (the pilot's arm switch) ..."]


def test_a_board_already_armed_starts_at_once(board_session):
    board, session = board_session
    board.send_samples(2, armed=True)
    session.hover(lambda text: pytest.fail(text))


def test_a_board_never_armed_or_silent_ends_with_one_line(board_session, monkeypatch):
    from heliquad.host import session as session_module

    board, session = board_session
    monkeypatch.setattr(session_module, "FIRST_SAMPLE_WAIT_S", 0.0)
    with pytest.raises(InputError, match=f"^no samples from the board in 0 s: is {board.port} "
                                         "its telemetry port, and is it running\\?$"):
        session.hover(print)
    monkeypatch.setattr(session_module, "ARM_WAIT_S", 0.0)
    board.send_samples(1, armed=False)
    with pytest.raises(InputError, match="^the board was not armed within 0 s; arm it, then "
                                         "run the sweep again$"):
        session.hover(lambda text: None)
