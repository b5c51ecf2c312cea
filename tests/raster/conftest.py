import pytest

from serenity.raster.context import check_gl_error, get_context


@pytest.fixture(scope="session")
def gl_ctx():
    return get_context()


@pytest.fixture(autouse=True)
def _no_gl_error(request):
    """Every GL test ends with the GL error flag clear."""
    yield
    if "gl_ctx" in request.fixturenames:
        check_gl_error(request.getfixturevalue("gl_ctx"), request.node.name)
