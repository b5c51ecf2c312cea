import pytest


@pytest.fixture(scope="session")
def gl_ctx():
    from serenity.raster.context import get_context

    return get_context()
