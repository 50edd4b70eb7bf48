"""The host's telemetry link when the other end goes away."""

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
