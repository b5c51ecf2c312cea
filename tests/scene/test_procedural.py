"""The built-in scenes' derived geometry: what ``Scene.content_bounds`` keeps."""


def test_content_bounds_leave_out_the_ground_plane_only():
    """``Scene.content_bounds``: the courtyard's 120 m ground plane is left out (its buildings span
    ±23.3 m, widened by 10 % of that on each side), a scene that is only a ground plane keeps its
    bounds, and a terrain (not flat) is all content."""
    import numpy as np

    from serenity.scene.procedural import build_scene, plane_scene

    court = build_scene("courtyard")
    lo, hi = court.content_bounds()
    assert np.allclose(lo[[0, 2]], -23.3 - 0.1 * 46.6, atol=0.05) and np.allclose(hi[[0, 2]], 23.3 + 4.66, atol=0.05)
    assert lo[1] == court.bounds[0, 1] and hi[1] == court.bounds[1, 1]
    plane = plane_scene()
    assert np.array_equal(plane.content_bounds(), plane.bounds)
    terrain = build_scene("terrain")
    assert np.allclose(terrain.content_bounds(), terrain.bounds)
