"""Start a process as a terminal would, whatever started the test run.

bash starts a background job without job control with SIGINT ignored, and a process inherits that
(Python then never installs its KeyboardInterrupt handler). A test suite launched that way (`make test &`
from a script) would start every campaign it tests deaf to Ctrl-C. Tests that press Ctrl-C start their
process with `preexec_fn=as_from_a_terminal`, so they test preland, not how the suite was launched."""

from __future__ import annotations

import signal


def as_from_a_terminal() -> None:
    """In the child, before exec: SIGINT back to its default action and unblocked."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])
