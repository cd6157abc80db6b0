import signal
import pytest


@pytest.fixture(autouse=True)
def _sigint_guard(request):
    yield
    h = signal.getsignal(signal.SIGINT)
    if h is not signal.default_int_handler:
        print(f"\nSIGINT HANDLER CHANGED after {request.node.nodeid}: {h}")
