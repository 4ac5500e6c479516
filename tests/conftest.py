import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def forget_user_laws():
    """The user laws a test loads leave with it: other tests list every law of the process."""
    from tensormass import laws
    before = dict(laws._user)
    yield
    laws._user.clear()
    laws._user.update(before)
