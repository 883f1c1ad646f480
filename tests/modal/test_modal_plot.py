"""``ModalModel.plot`` draws through the viewers (the modal room never imports matplotlib)."""

from __future__ import annotations

import numpy as np

import vibroscope.modal as modal


def test_modal_model_plot(tmp_path):
    """``ModalModel.plot`` delegates to the viewers' ``plot_mode_shapes`` (matplotlib, Agg): one
    panel per mode, titled with its frequency."""
    from PIL import Image

    m = modal.ModalModel(natural_frequencies=[2.0, 5.0], damping_ratios=[0.01, 0.02],
                         shapes=[[1, 0.5, 0.2], [-0.3, 1, 0.4]], points=["a", "b", "c"], method="fdd")
    fig = m.plot()
    titles = [ax.get_title() for ax in fig.axes]
    assert any("2 Hz" in t for t in titles) and any("5 Hz" in t for t in titles), titles
    fig.savefig(tmp_path / "modes.png")
    with Image.open(tmp_path / "modes.png") as im:
        assert im.size[0] > 200 and im.size[1] > 200
    assert np.isfinite(m.natural_frequencies).all()
