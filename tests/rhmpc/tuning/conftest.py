"""The ``slow`` marker: tests over about 2 s (``pytest -m "not slow"`` leaves them out)."""


def pytest_configure(config) -> None:
    config.addinivalue_line("markers", "slow: a test that takes more than about 2 s")
