"""Real and generated people transplanted into each other's scans: a person with its whole turn
moved is what it was in its own scan; no person in the band is bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from conftest import generate_test16, net_for, save_model
from pedscan_data.reader import Sequence
from pedscan_data.transplant import BACKDROP_COLUMNS, alone, backdrop, main, narrower, transplant


@pytest.fixture(scope="module")
def scans(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """pedscan's SemanticKITTI export of two sequences, and a model file on their grid."""
    tmp = tmp_path_factory.mktemp("transplant")
    out = generate_test16(tmp, "--sequences", "2", "--frames", "2", "--humans", "8..10", "--seed", "7", "--formats", "h5,semantickitti")
    seq = Sequence(out / "seq_000000.h5")
    model = save_model(net_for(1, width=4, seed=2), tmp / "net.pt", threshold=0.5)
    obj = torch.load(model, weights_only=True)
    obj["sensor"] = {"name": seq.sensor, "elevation_deg": seq.elevation_deg.tolist(), "columns": seq.columns}
    torch.save(obj, model)
    return out / "semantickitti", model


def test_a_person_moved_with_its_whole_turn_is_what_it_was(scans: tuple[Path, Path]) -> None:
    folder, model = scans
    # 256 columns either side of a 512-column grid: the whole scan goes with the person.
    d = transplant(model, folder, folder, columns=256, band=(0.0, 100.0))
    s = d["settings"]
    assert s["real"]["people"] >= 8 and s["real"] == s["generated"] == s["real in generated"] == s["generated in real"]
    assert 0.0 <= s["real"]["found"] <= 1.0
    assert s["real, backdrop pushed back"] == s["generated, backdrop pushed back"]
    assert s["real, alone"] == s["generated, alone"] and s["real, alone, a quarter narrower"] == s["generated, alone, a quarter narrower"]
    assert s["real, alone"] != s["real"], "alone, the people's surroundings are gone"
    assert d["backdrop_share"]["real"] == d["backdrop_share"]["generated"]
    # With no surroundings moved, people land among other scans' beams: other margins.
    near = transplant(model, folder, folder, columns=0, band=(0.0, 100.0))["settings"]
    assert near["real"] == s["real"] and near["real in generated"] != s["real in generated"]


def test_the_command_writes_its_figures_and_refuses_a_band_without_people(scans: tuple[Path, Path], tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    folder, model = scans
    out = tmp_path / "t.json"
    assert main([str(model), str(folder), str(folder), "--range", "0", "100", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["settings"]["real"]["people"] >= 8
    assert "real in generated" in capsys.readouterr().out
    assert main([str(model), str(folder), str(folder), "--range", "500", "600"]) == 2
    assert f"{folder}: no person at 500-600 m" in capsys.readouterr().err
    assert main([str(model), str(folder), str(folder), "--columns", "-1"]) == 2


def test_a_backdrop_is_what_stands_0_to_2_m_behind_a_person_in_its_rows_beside_it() -> None:
    import numpy as np

    image = np.full((8, 512), 30.0, dtype=np.float32)
    rows, cols = np.repeat([2, 3, 4], 3), np.tile([100, 101, 102], 3)
    image[rows, cols] = 10.0  # the person
    image[2:5, 90:100] = 11.0  # a wall 1 m behind, left of it
    image[3, 103] = 5.0  # a post in front
    image[4, 104] = 0.0  # no return
    image[6, 95:100] = 11.0  # below its rows: not looked at
    image[2, 101 + BACKDROP_COLUMNS + 1] = 11.0  # beyond the columns looked at
    mask, looked = backdrop(image, rows, cols, 10.0)
    assert looked == 3 * (2 * BACKDROP_COLUMNS + 1) - 9
    assert set(zip(*np.nonzero(mask))) == {(r, c) for r in (2, 3, 4) for c in range(90, 100)}


def test_alone_keeps_the_person_and_the_ground_and_narrower_takes_the_outer_eighths() -> None:
    import numpy as np

    image = np.full((6, 512), 30.0, dtype=np.float32)
    ground = np.zeros(image.shape, bool)
    ground[5] = True
    rows = np.array([2] * 8 + [3] * 2 + [4] * 8)
    cols = np.concatenate([np.arange(100, 108), [103, 104], (np.arange(508, 516) % 512)])
    image[rows, cols] = 10.0
    out = alone(image, ground, rows, cols)
    assert (out[rows, cols] == 10.0).all() and (out[5] == 30.0).all()
    assert np.count_nonzero(out) == len(rows) + 512
    keep = narrower(rows, cols, 512)
    # 8 cells a row: one off either end; 2 cells: none; across the seam by columns from its centre.
    assert set(cols[~keep][rows[~keep] == 2]) == {100, 107}
    assert keep[rows == 3].all()
    assert set(cols[~keep][rows[~keep] == 4]) == {508, 3}


def test_margins_are_grown_where_the_model_file_asks(scans: tuple[Path, Path], tmp_path: Path) -> None:
    folder, model = scans
    plain = transplant(model, folder, folder, columns=256, band=(0.0, 100.0))["settings"]["real"]
    obj = torch.load(model, weights_only=True)
    obj["grow"] = {"margin": -30.0, "step_m": 100.0}  # every returned beam joined: each takes its scan's highest
    torch.save(obj, tmp_path / "grown.pt")
    grown = transplant(tmp_path / "grown.pt", folder, folder, columns=256, band=(0.0, 100.0))["settings"]["real"]
    assert grown["people"] == plain["people"] and grown["median_margin"] > plain["median_margin"]
