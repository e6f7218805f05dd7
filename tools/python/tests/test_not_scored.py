"""Not-scored beams (``/label`` 255, a recorded background's own people): the training loss and
the class weight leave them out, whatever the network says there."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pedscan_data import class_weight
from pedscan_data.evaluate import NOT_SCORED
from pedscan_data.train import paper_loss


def batch(seed: int) -> tuple[torch.Tensor, ...]:
    """Logits, velocities and targets of one 4 x 8 frame: two human beams, one no-return beam,
    and two not-scored beams (one of them without a return)."""
    g = torch.Generator().manual_seed(seed)
    h, w = 4, 8
    logits = torch.randn(1, 2, h, w, generator=g)
    velocity = torch.randn(1, 3, h, w, generator=g)
    v_true = torch.randn(1, 3, h, w, generator=g)
    label = torch.zeros(1, h, w, dtype=torch.int64)
    label[0, 1, 2:4] = 1
    label[0, 2, 5] = NOT_SCORED
    label[0, 3, 0] = NOT_SCORED
    valid = torch.ones(1, h, w, dtype=torch.bool)
    valid[0, 0, 7] = False
    valid[0, 3, 0] = False
    return logits, velocity, label, v_true, valid


def test_a_not_scored_beam_adds_nothing_to_the_loss_whatever_the_network_says_there() -> None:
    logits, velocity, label, v_true, valid = batch(3)
    loss, terms = paper_loss(logits, velocity, label, v_true, valid)
    # The same frame with the not-scored beams taken as no-return beams: the same loss.
    unscored = label == NOT_SCORED
    as_holes, _ = paper_loss(logits, velocity, label.masked_fill(unscored, 0), v_true, valid & ~unscored)
    assert float(loss) == pytest.approx(float(as_holes), rel=1e-6)
    # Any logits and velocities there: the loss does not move, and no gradient reaches them.
    logits2, velocity2 = logits.clone(), velocity.clone()
    logits2[0][:, unscored[0]] = torch.tensor([[-40.0], [40.0]])
    velocity2[0][:, unscored[0]] = 25.0
    loss2, terms2 = paper_loss(logits2, velocity2, label, v_true, valid)
    assert float(loss2) == pytest.approx(float(loss), rel=1e-6)
    assert terms2 == pytest.approx(terms, rel=1e-6)
    logits3 = logits.clone().requires_grad_(True)
    velocity3 = velocity.clone().requires_grad_(True)
    paper_loss(logits3, velocity3, label, v_true, valid)[0].backward()
    assert torch.all(logits3.grad[0][:, unscored[0]] == 0)
    assert torch.all(velocity3.grad[0][:, unscored[0]] == 0)
    # A scored background beam does move it (the check above can fail).
    logits2[0, :, 0, 0] = torch.tensor([-40.0, 40.0])
    assert float(paper_loss(logits2, velocity, label, v_true, valid)[0]) > float(loss) + 1.0


def test_the_class_weight_counts_scored_beams_only() -> None:
    label = np.zeros((2, 6), dtype=np.uint8)
    label[0, :2] = 1
    label[1, :3] = NOT_SCORED
    range_m = np.full((2, 6), 10.0, dtype=np.float32)
    range_m[1, 5] = 0.0
    # 11 returns: 2 human, 3 not scored, 6 background.
    assert class_weight(label, range_m) == pytest.approx(6 / 2)
    # Not-scored beams alone are no human beams: weight 1.
    assert class_weight(np.where(label == 1, 0, label).astype(np.uint8), range_m) == 1.0
