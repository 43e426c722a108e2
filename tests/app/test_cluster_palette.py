"""The clusters layer's colours (app/scene/clusters.py): a palette per kind, slots carried over to the clusters that
stay between fits, per-voxel colours from the labels, the focus dimming the rest."""

from __future__ import annotations

import numpy as np

from app.scene.clusters import DIM, DIM_TOWARDS, PALETTES, carry_slots, cluster_colors, voxel_colors


def test_each_kind_has_its_own_distinct_colours() -> None:
    occ, fro = PALETTES["occupied"], PALETTES["frontier"]
    assert len(set(occ)) == len(occ) >= 10 and len(set(fro)) == len(fro) >= 10
    assert not set(occ) & set(fro)


def test_a_first_fit_takes_slots_in_order() -> None:
    centers = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    assert carry_slots(np.zeros((0, 3)), np.zeros(0), [], centers, np.full(3, 0.1)) == [0, 1, 2]


def test_clusters_that_stay_keep_their_slot_and_new_ones_take_the_free_ones() -> None:
    prev = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    prev_slots = [0, 1, 2]
    # the cluster at x=1 is gone, the one at x=2 moved a little, a new one at x=5, the one at 0 listed last
    new = np.array([[2.05, 0, 0], [5, 0, 0], [0.02, 0, 0]])
    slots = carry_slots(prev, np.full(3, 0.2), prev_slots, new, np.full(3, 0.2))
    assert slots == [2, 1, 0]  # x=2 keeps 2, x=0 keeps 0, the new one takes the lowest free slot (1)
    # too far (beyond both major semi-axes): a new slot, not the old one's
    assert carry_slots(prev[:1], np.array([0.05]), [4], np.array([[0.5, 0, 0]]), np.array([0.05])) == [0]


def test_two_new_clusters_near_one_old_one_share_nothing() -> None:
    prev, prev_slots = np.array([[0.0, 0, 0]]), [3]
    new = np.array([[0.1, 0, 0], [0.02, 0, 0]])
    slots = carry_slots(prev, np.array([0.5]), prev_slots, new, np.full(2, 0.5))
    assert slots == [0, 3]  # the closest one keeps slot 3, the other takes the lowest free one


def test_voxel_colours_follow_the_labels_and_the_palette_repeats() -> None:
    palette = PALETTES["frontier"]
    labels = np.array([1, 0, 0, 2])
    slots = [0, 5, len(palette) + 1]  # the third wraps around to slot 1
    colors = voxel_colors(labels, slots, palette, None)
    assert colors.dtype == np.uint8 and colors.shape == (4, 3)
    assert [tuple(c) for c in colors] == [palette[5], palette[0], palette[0], palette[1]]


def test_a_focus_keeps_its_cluster_s_colour_and_dims_the_rest() -> None:
    palette = PALETTES["occupied"]
    labels = np.array([0, 1, 1, 2])
    colors = voxel_colors(labels, [0, 1, 2], palette, 1)
    assert tuple(colors[1]) == tuple(colors[2]) == palette[1]
    expected = np.round(np.asarray(palette[0], float) + DIM * (DIM_TOWARDS - np.asarray(palette[0], float)))
    assert np.array_equal(colors[0], expected.astype(np.uint8))
    assert colors[[0, 3]].min() > 150  # dimmed towards light grey
    # -1: a focus on the other kind dims every cluster of this one
    assert all(min(c) > 150 for c in cluster_colors([0, 1, 2], palette, -1))
