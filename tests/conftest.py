import pytest


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the project's default variant and plugins registered."""
    from skyfit_mi.render import setup

    return setup()
