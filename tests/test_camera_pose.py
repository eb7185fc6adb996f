"""The camera from marked points (pipeline/camera_pose.py): pose, focal length and distortion
recovered from a synthetic camera, their uncertainty's coverage, the [camera] TOML read back,
undistortion, and every bad input refused with nothing written."""

import re

import cv2
import numpy as np
import pytest

from skyfit_mi.cli import main
from skyfit_mi.errors import SkyfitError
from skyfit_mi.physics.lens import focal_px
from skyfit_mi.pipeline.camera_pose import (MarkedPoints, estimate_camera, read_points,
                                            write_camera)
from skyfit_mi.pipeline.registration import undistort_image
from skyfit_mi.pipeline.spec import SpecError, read_spec, validate_spec
from skyfit_mi.render.scene import camera_matrix, camera_origin, look_at

#: The issue's camera: a 0.6 x 0.4 m board at the origin seen from 3 m, 37 degrees from the
#: vertical, from the east (azimuth 90), 30 degree field of view, 640 x 480, barrel k1 = -0.1.
W, H, FOV, K1, AZ, ANGLE, DIST = 640, 480, 30.0, -0.1, 90.0, 37.0, 3.0
TO_WORLD = look_at(camera_origin(AZ, ANGLE, DIST), [0.0, 0.0, 0.0])
CORNERS = [(x, y, 0.0) for x in (-0.3, 0.3) for y in (-0.2, 0.2)]
BOARD6 = np.array(CORNERS + [(0.0, 0.2, 0.0), (0.0, -0.2, 0.0)])
#: The board's corners and two posts 0.5 m tall beside it: not coplanar.
POSTS = np.array(CORNERS + [(0.35, 0.0, 0.5), (-0.35, 0.0, 0.5), (0.0, 0.3, 0.5),
                            (0.0, -0.3, 0.5)])


def project(world, to_world=TO_WORLD, fov=FOV, k1=K1):
    """Pixels [px] of world points through the Mitsuba camera ``to_world`` (columns left, up,
    forward), written out here independently of OpenCV."""
    cam = (world - to_world[:3, 3]) @ to_world[:3, :3]           # left, up, forward
    x = -cam[:, :2] / cam[:, 2:]                                 # right, down
    x = x * (1 + k1 * np.sum(x ** 2, axis=1, keepdims=True))
    return focal_px(fov, W) * x + [(W - 1) / 2, (H - 1) / 2]


def marks(world, seed, sd=0.5, **kw):
    uv = project(world, **kw) + np.random.default_rng(seed).normal(0.0, sd, (len(world), 2))
    return MarkedPoints(tuple(f"p{i}" for i in range(len(world))), uv, world)


def placement_errors(est):
    p = est.placement()
    truth = {"azimuth_deg": AZ, "angle_deg": ANGLE, "distance_m": DIST, "fov_deg": FOV,
             "roll_deg": 0.0}                     # look_at's camera: its up in the vertical
    return {k: (p[k][0] - v, p[k][1]) for k, v in truth.items()}


def test_pose_from_six_board_points_with_the_focal_length_given():
    """The issue's goal, 0.1 degree from six coplanar points marked to 0.5 px, is out of reach
    of this view: the board spans 240 px, and its tilt shows only through foreshortening, so the
    stated 1-sigma is 0.47 degree in azimuth and 0.27 in angle (docs/cli.md, "camera"); the
    errors over 50 seeds match it."""
    errs = np.array([[e for e, _ in placement_errors(estimate_camera(
        marks(BOARD6, seed), W, H, FOV, [K1], target=[0, 0, 0])).values()]
        for seed in range(50)])
    rms = np.sqrt(np.mean(errs ** 2, axis=0))
    assert rms[0] < 0.6 and rms[1] < 0.35 and rms[2] < 0.01           # deg, deg, m
    assert np.all(errs[:, 3] == pytest.approx(0.0, abs=1e-9))         # the fov as given
    exact = estimate_camera(marks(BOARD6, 0, sd=0.0), W, H, FOV, [K1], target=[0, 0, 0])
    assert all(abs(e) < 1e-6 for e, _ in placement_errors(exact).values())
    assert np.allclose(exact.to_world(), TO_WORLD, atol=1e-8)


def test_points_off_the_board_plane_reach_a_tenth_of_a_degree_at_one_sigma():
    """Four corners and four points 0.5 m above the board: 1-sigma 0.13 degree (azimuth) and
    0.08 (angle) with the focal length given, 0.46 degree in the fitted fov without it."""
    p = estimate_camera(marks(POSTS, 0), W, H, FOV, [K1], target=[0, 0, 0]).placement()
    assert p["azimuth_deg"][1] < 0.15 and p["angle_deg"][1] < 0.1
    est = estimate_camera(marks(POSTS, 1), W, H, target=[0, 0, 0])
    assert est.free == ("r1", "r2", "r3", "t1", "t2", "t3", "focal", "k1")
    err = placement_errors(est)
    assert abs(err["fov_deg"][0]) < 3 * err["fov_deg"][1] and err["fov_deg"][1] < 0.8
    assert abs(est.k[0] - K1) < 3 * est.placement()["k1"][1]


@pytest.mark.parametrize("world,fov", [(BOARD6, FOV), (POSTS, FOV), (POSTS, None)],
                         ids=["board, fov given", "posts, fov given", "posts, fov fitted"])
def test_uncertainty_covers_the_truth_at_its_stated_level(world, fov):
    """Over 50 seeds, the truth lies within 1.96 stated sigma about 95% of the time: 44 or more
    (a binomial(50, 0.95) falls below 44 with probability 1.2%); the roll's too, which the
    written pose_sd_deg carries."""
    hits = np.zeros(5, int)
    for seed in range(50):
        err = placement_errors(estimate_camera(marks(world, seed), W, H, fov,
                                               [K1] if fov else None, target=[0, 0, 0]))
        hits += [abs(e) <= 1.96 * s for e, s in err.values()] if fov is None else \
            [abs(e) <= 1.96 * s if k != "fov_deg" else 1 for k, (e, s) in err.items()]
    assert np.all(hits >= 44), hits


def test_written_camera_reads_back_through_the_spec(tmp_path):
    from dataclasses import replace

    est = replace(estimate_camera(marks(BOARD6, 3), W, H, FOV, [K1]), photo="IMG_0002.jpg")
    toml, report = write_camera(est, tmp_path / "camera.toml")
    raw = read_spec(toml)
    spec = {"name": "t", "location": {"latitude_deg": 40.0, "longitude_deg": 0.0,
                                      "timezone": "UTC"},
            "time": {"date": "2026-06-21", "times": ["12:00"]}, "scene": {"file": "disc.xml"},
            **raw}
    cam = validate_spec(spec, tmp_path).camera
    assert np.allclose(camera_matrix(cam), est.to_world(), atol=1e-12)
    assert cam["distortion"] == [K1, 0.0] and cam["fov_deg"] == pytest.approx(FOV)
    assert report.exists() and "azimuth" in toml.read_text()
    assert cam["photo"] == "IMG_0002.jpg"              # the frame ingest registers on
    roll = est.placement()["roll_deg"][1]
    assert roll > 0 and cam["pose_sd_deg"]["roll"] == pytest.approx(roll)


def test_spec_refuses_a_distortion_that_folds_the_image():
    cam = {"origin": [3.0, 0.0, 2.0], "fov_deg": 90.0, "width": 640, "height": 480}
    base = {"name": "t", "scene": {"file": "disc.xml"},
            "sky": [{"type": "directional", "direction": [0, 0, 1], "irradiance_W_m2": 1.0}]}
    for k, msg in (([-0.5], "folds the image"), ("x", r"\[k1\] or \[k1, k2\]"),
                   ([0.1, "a"], "must be a number")):
        with pytest.raises(SpecError, match=msg):
            validate_spec({**base, "camera": {**cam, "distortion": k}})


def test_undistort_image_inverts_a_synthetic_distortion():
    """A smooth pattern of the pinhole's pixels, distorted by k1, k2, comes back within 1% of
    its range where the map stays on the photograph."""
    camera = {"fov_deg": 60.0, "width": 160, "height": 120, "distortion": [-0.2, 0.05]}
    f, c = focal_px(60.0, 160), np.array([79.5, 59.5])

    def pattern(u, v):
        return np.stack([np.sin(u / 9.0) * np.cos(v / 7.0), u / 160.0], axis=-1)

    v, u = np.mgrid[0:120, 0:160].astype(float)
    ideal = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2),
                                np.array([[f, 0, c[0]], [0, f, c[1]], [0, 0, 1]]),
                                np.array([-0.2, 0.05, 0, 0])).reshape(120, 160, 2) * f + c
    photo = pattern(ideal[..., 0], ideal[..., 1])                  # what the lens records
    back = undistort_image(photo, camera)
    inside = np.all(np.isfinite(back), axis=-1)
    assert inside[20:100, 20:140].all() and back.dtype == np.float64
    assert np.max(np.abs(back - pattern(u, v))[inside]) < 0.02
    assert undistort_image(photo, {**camera, "distortion": [0.0]}) is not photo
    with pytest.raises(SkyfitError, match="undistort photographs of the camera's size"):
        undistort_image(photo[:10], camera)


def _csv(path, world, uv, names=None):
    names = names or [f"p{i}" for i in range(len(world))]
    path.write_text("name,x_px,y_px,X,Y,Z\n" + "".join(
        f"{n},{u},{v},{x},{y},{z}\n" for n, (u, v), (x, y, z) in zip(names, uv, world)))
    return path


def test_cli_writes_the_camera_and_its_report(tmp_path, capsys):
    pts = _csv(tmp_path / "pts.csv", BOARD6, marks(BOARD6, 0).image)
    out = tmp_path / "cam.toml"
    args = ["camera", str(pts), "--width", "640", "--height", "480", "--fov-deg", "30",
            "--distortion", "-0.1", "--target", "0,0,0", "-o", str(out)]
    assert main(args) == 0
    said = capsys.readouterr().out
    assert re.match(r"camera from 6 points: azimuth 89\.\d\d \+- 0\.4\d deg, 3\d\.\d\d \+- 0\.2\d "
                    r"deg from vertical, 2\.99\d \+- 0\.00\d m from \[0, 0, 0\].*reprojection rms",
                    said), said
    assert out.exists() and out.with_suffix(".json").exists()
    assert main(args) == 2                                     # no overwrite
    assert "exists" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    from PIL import Image
    Image.new("RGB", (W, H)).save(tmp_path / "photo.png")
    size = args.index("--width")
    assert main(args[:size] + ["--photo", str(tmp_path / "photo.png")] + args[size + 4:]
                + ["--overwrite"]) == 0


def _behind():
    """Six board points and a seventh behind the camera, marked where the pinhole's
    projection (through the camera's centre) puts it: a scene coordinate of the wrong sign."""
    o = TO_WORLD[:3, 3]
    world = np.r_[BOARD6, [o + 0.5 * o + [0.1, 0.0, 0.0]]]
    return world, project(world)


MISLABELLED = project(BOARD6)
MISLABELLED[1] = MISLABELLED[3]               # p1 marked on p3's corner


@pytest.mark.parametrize("world,uv,extra,msg", [
    (BOARD6, project(BOARD6) + [700, 0], [], r"\(p0\): the mark \(.*\) px is off the 640x480"),
    (BOARD6[:3], project(BOARD6[:3]), [], "3 marked point.*at least 4"),
    (BOARD6[:5], project(BOARD6[:5]), ["--fov-deg"], "5 marked point.*at least 6"),
    (np.c_[np.linspace(0, 1, 6), np.zeros((6, 2))], np.c_[np.linspace(100, 400, 6),
                                                          np.linspace(100, 300, 6)],
     [], "lie on one line in the scene"),
    (*_behind(), [], "p6 behind it"),
    (BOARD6, MISLABELLED, [], "point 'p1' is the likeliest mislabelled"),
    # a plane's mirror image fits a camera below it as well as the truth from above
    (BOARD6, project(BOARD6) * [1, -1] + [0, H - 1], [], "below the ground and the marked"),
    (BOARD6[:, [1, 0, 2]], project(BOARD6), [], "below the ground and the marked"),
], ids=["off the image", "three points", "five, fov free", "collinear", "behind",
        "mislabelled", "rows counted up", "east and north swapped"])
def test_bad_inputs_exit_2_and_write_nothing(tmp_path, capsys, world, uv, extra, msg):
    pts = _csv(tmp_path / "pts.csv", world, uv)
    args = ["camera", str(pts), "--width", "640", "--height", "480", "-o",
            str(tmp_path / "cam.toml")]
    if extra != ["--fov-deg"]:
        args += ["--fov-deg", "30", "--distortion", "-0.1"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("skyfit: error:")
    assert re.search(msg, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pts.csv"]


@pytest.mark.parametrize("text,msg", [
    ("name,x_px,y_px,X,Y,Z\na,1,2,0,0,zero\n", r"line 2 \(a\): Z = 'zero' is not a finite"),
    ("name,x_px,y_px,X,Y,Z\na,1,2,0,0,0\na,3,4,1,0,0\n", "'a' is given twice"),
    ("name,x,y,X,Y,Z\na,1,2,0,0,0\n", "lacks column.*x_px, y_px"),
    ("x_px,y_px,X,Y,Z\n1,nan,0,0,0\n", r"line 2 \(row 2\): y_px = 'nan'"),
    ("name,x_px,y_px,X,Y,Z\na,1,2,0,3,0,0\n", "line 2 has more cells than the header's 6"),
    ("name,x_px,y_px,X,Y,Z\na,1,2,0\n", "line 2 has fewer cells"),
])
def test_points_file_errors(tmp_path, text, msg):
    (tmp_path / "p.csv").write_text(text)
    with pytest.raises(SkyfitError, match=msg):
        read_points(tmp_path / "p.csv", W, H)


def test_a_board_seen_face_on_does_not_give_the_focal_length():
    face_on = look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0])
    world = np.array([(x, y, 0.0) for x in (-0.3, 0.0, 0.3) for y in (-0.2, 0.2)])
    pts = marks(world, 0, to_world=face_on, k1=0.0)
    with pytest.raises(SkyfitError, match="do not determine the focal length|two camera poses"):
        estimate_camera(pts, W, H)


#: Twelve ground points over most of the image (its corners at 0.9 of the half-diagonal).
GRID = np.array([(x, y, 0.0) for x in np.linspace(-0.55, 0.55, 3)
                 for y in np.linspace(-0.65, 0.65, 4)])


def test_marks_reaching_the_corners_fit_the_distortion_or_reject_a_wrong_one():
    """With the field of view given, marks that reach the image's corners fit k1 (and k2)
    with the pose where they ask for it (chi^2 falls by over 9 with it), so a lens left without
    --distortion is not taken as distortion-free; a
    given k1 of the wrong sign is refused (the marks' chi^2 falls by over 9 with k1 fitted; a
    given 0 for the true -0.1 falls by 2-13 over seeds 0-4, so the test does not always tell
    it); the true one is kept as given."""
    uv = project(GRID)
    assert np.all((uv >= 0) & (uv <= [W - 1, H - 1]))
    pts = marks(GRID, 1)
    free = estimate_camera(pts, W, H, FOV, None, target=[0, 0, 0]).placement()
    assert set(free) >= {"k1", "k2"} and abs(free["k1"][0] - K1) < 3 * free["k1"][1]
    assert abs(free["distance_m"][0] - DIST) < 3 * free["distance_m"][1]
    with pytest.raises(SkyfitError, match="--distortion k1 = 0.1 disagrees"):
        estimate_camera(pts, W, H, FOV, [0.1], target=[0, 0, 0])
    given = estimate_camera(pts, W, H, FOV, [K1], target=[0, 0, 0])
    assert "k1" not in given.free and given.k[0] == K1
    # four far corners of a distortion-free lens: the marks do not ask for a k1 (its chi^2
    # falls by under 9), so none is made up from one degree of freedom
    corners = GRID[[0, 3, 8, 11]]
    for seed in range(5):
        est = estimate_camera(marks(corners, seed, k1=0.0), W, H, FOV, None, target=[0, 0, 0])
        assert "k1" not in est.free and not np.any(est.k), (seed, est.k)
