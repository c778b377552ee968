import pytest


@pytest.fixture(autouse=True)
def _one_torch_thread(one_torch_thread):
    """Every agent test runs torch on one thread (``tests/conftest.py``)."""
