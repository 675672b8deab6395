"""inform_utils/contact_check.py's pure parts: the largest gap between two recordings of the object's path and where it
first exceeds 1 mm, the model constants that differ, and the packing of the constants into a recording."""

import numpy as np

from inform_utils.contact_check import differing_constants, pack, path_gap, unpack


def test_path_gap_finds_the_largest_gap_and_where_it_first_exceeds_1mm():
    a = np.zeros((3, 5, 2))
    a[2, 1:] = [0.1, 0.0]  # episode 2's object moves 0.1 m at step 1
    b = a.copy()
    b[1, 3] += [0.0003, 0.0004]  # 0.5 mm: under the 1 mm
    b[2, 2] += [0.003, 0.004]  # 5 mm at step 2
    b[0, 4] += [0.0012, 0.0]  # 1.2 mm at step 4
    gap = path_gap(a, b)
    assert np.isclose(gap["largest"], 0.005)
    assert (gap["episode"], gap["step"]) == (2, 2)
    assert gap["first_over"] == 2  # the first step at which any episode's gap exceeds 1 mm
    assert (gap["episodes_over"], gap["episodes"]) == (2, 3)
    assert np.isclose(gap["moved"], 0.1)
    assert np.isclose(gap["median"], 0.0012)  # the episodes' largest gaps: 1.2, 0.5 and 5 mm
    assert path_gap(a, a)["largest"] == 0.0 and path_gap(a, a)["first_over"] is None


def test_differing_constants_names_values_beyond_the_tolerance_and_shapes():
    a = {"same": np.array([1.0, 0.0]), "tiny": np.array(3.0), "value": np.array([2.0, 4.0, 0.0]), "shape": np.zeros(2)}
    b = {"same": np.array([1.0, 0.0]), "tiny": np.array(3.0 + 1e-12), "value": np.array([2.0, 5.0, 0.0]),
         "shape": np.zeros(3), "only_in_b": np.ones(1)}  # fmt: skip
    out = differing_constants(a, b)
    assert set(out) == {"value", "shape"}
    assert out["value"] == (1, 3, 0.2)  # |4 - 5| / 5
    assert out["shape"][0] == -1


def test_pack_and_unpack_keep_every_constant():
    consts = {"nbody": np.array(13), "body_invweight0": np.arange(26.0).reshape(13, 2), "empty": np.zeros((0, 3)),
              "opt.timestep": np.array(0.01)}  # fmt: skip
    back = unpack(**pack(consts))
    assert set(back) == set(consts)
    for name, value in consts.items():
        assert back[name].shape == value.shape and np.array_equal(back[name], value)
