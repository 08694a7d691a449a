"""E-4DGS reads the sensor of the event file it trains on: a scene simulated with contrast thresholds
C+ = 0.3, C- = 0.2 and the lin-log response (not the simulator's defaults, C = 0.2 and log) gives a
loss built from those values, and not the one the defaults would give."""
import numpy as np
import pytest
import torch
import yaml

from recon import event_supervision as ev
from recon.api import construct_method, resolve_config
from recon.trainer import Trainer
from scene_format.reader import SceneDataset
from simulator import SimulatorConfig


@pytest.fixture(scope="module")
def linlog_scene(tmp_path_factory):
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    preset = yaml.safe_load((root / "tests" / "fixtures" / "configs" / "datasets" / "tiny_motion.yaml").read_text())
    preset["overrides"]["sensor"] = {"log_mode": "linlog", "pos_threshold": 0.3, "neg_threshold": 0.2}
    out = tmp_path_factory.mktemp("tiny_linlog")
    (out / "tiny_linlog.yaml").write_text(yaml.safe_dump(preset))
    r = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset",
                        str(out / "tiny_linlog.yaml"), "--out", str(out / "data"), "--no-progress"],
                       capture_output=True, text=True, cwd=root)
    assert r.returncode == 0, r.stderr
    return out / "data" / "cubes"


def _loss_by_hand(method, trainer, window, sensor: SimulatorConfig) -> float:
    """The event loss of one window from its events and the given sensor's thresholds and response."""
    ds, e = method.dataset, method.cfg.events
    t_s, t_e = window.t_start_us / ds.duration_us, window.t_end_us / ds.duration_us
    from recon.dataset_views import dataset_camera

    cam_s, cam_e = dataset_camera(ds, window.camera, window.t_start_us), dataset_camera(ds, window.camera, window.t_end_us)
    img_s = trainer.model.render_outputs([cam_s], t_s, trainer.backend)[0].image
    img_e = trainer.model.render_outputs([cam_e], t_e, trainer.backend)[0].image

    def response(img):
        lum = ev.luminance_t(ev.srgb_to_linear_t(img))
        return ev.log_response_t(lum, sensor.log_mode, sensor.log_eps, sensor.linlog_threshold_dn, sensor.linlog_dn_per_unit)

    c_pos, c_neg = sensor.pos_threshold, sensor.neg_threshold
    de, hits = ev.event_maps(window.x, window.y, window.p, ds.intrinsics.width, ds.intrinsics.height, c_pos, c_neg)
    n_gt = torch.from_numpy(ev.gt_counts(de, hits, 0.5 * (c_pos + c_neg), 0.0, np.random.default_rng(0)))
    n_pred = ev.predicted_counts(response(img_s), response(img_e), method.c_hat)
    return float(e.lambda_recon * ev.multiscale_recon_loss(n_gt, n_pred, e.loss_scales, e.recon_eps))


def test_the_e4dgs_loss_uses_the_event_files_thresholds_and_response(linlog_scene, tmp_path):
    ds = SceneDataset(linlog_scene)
    cfg = resolve_config("e4dgs", None, {"events.ess": False, "events.lambda_tv": 0.0, "train.init.n_points_object": 500,
                                         "train.init.color": "mid", "train.coarse_to_fine.factors": [],
                                         "train.coarse_to_fine.until": []})
    method = construct_method("e4dgs", ds, cfg)
    assert (method.c_pos, method.c_neg) == (0.3, 0.2) and method.response["mode"] == "linlog"
    trainer = Trainer(method, tmp_path / "run", progress=False)
    trainer.model = trainer.initial_model()
    torch.manual_seed(0)
    with torch.no_grad():                      # contrast in the model, so the responses differ in the loss
        trainer.model.gaussians.sh_dc.add_(2 * torch.rand_like(trainer.model.gaussians.sh_dc) - 1)
        trainer.model.gaussians.opacity_logits.add_(2.0)
    window = method.sampler.sample(np.random.default_rng(3))
    assert len(window) > 50
    with torch.no_grad():
        loss, _ = method.event_loss(trainer, [window])
        file_sensor = SimulatorConfig(log_mode="linlog", pos_threshold=0.3, neg_threshold=0.2)
        by_file = _loss_by_hand(method, trainer, window, file_sensor)
        by_default = _loss_by_hand(method, trainer, window, SimulatorConfig())
    assert float(loss) == pytest.approx(by_file, rel=1e-5)
    assert abs(by_default - by_file) > 0.05 * by_file       # reading the defaults would give another loss
