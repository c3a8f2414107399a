"""Change codes, the one definition (DESIGN.md §4): per point (3D labels) and per pixel (2D masks,
``label_ignore/`` in releases, ``siteline.release.metrics``)."""

UNCHANGED = 0
CHANGED = 1
IGNORE = 255
# per point only: the other scene did not observe the point's place (siteline.labels.change, the
# adaptive rule); a mask ignores its pixels (255) under the cause "not_observed"
NOT_OBSERVED = 254

# why a pixel is IGNORE, in the order a pixel is put under the first that holds:
# no_surface: neither scene has a point there, nor points around it (sky, the unscanned);
# gap: a scene has no point there but points all around it (sparse points the splats and the gap
#   fill left open: a 7 px closing of its render's hit mask fills it);
# one_side: one scene shows a surface where the other has none (a hole in one render only);
# outside_fence: a winning point lies outside the site fence;
# not_observed: a winning point's place the other scan did not observe (a wall it grazed or never saw,
#   ground where it has no point: siteline.labels.change, the adaptive rule);
# unsure_edge: the edge trim gave the pixel to a farther surface whose change differs from the nearer
#   one's whose splat reached it, or the pixel shows a farther surface through a nearer one's holes
#   or between the samples of a surface sparser than its tile (a pole's column): which of them it
#   shows is within a point spacing of an edge or a sample (siteline.pairs.render.unsure_edges; a
#   thin beam's sides, a moved car's rim, the ground between a new pole's samples);
# ignored_class: a winning point is of an ignored class (noise, snow, ignore) inside the fence.
IGNORE_CAUSES = (
    "no_surface",
    "gap",
    "one_side",
    "outside_fence",
    "not_observed",
    "unsure_edge",
    "ignored_class",
)
# a release adds the padding it writes around the rendered image (siteline.release.layout), and
# counts as unaccounted the ignore of outputs made before causes were recorded
RELEASE_IGNORE_CAUSES = (*IGNORE_CAUSES, "padding", "unaccounted")

# the generating software siteline's synthetic sites write into their LAS headers: a release whose
# scenes all carry it is synthetic, and says so (the dataset card, siteline.release.hub)
SYNTHETIC_SOFTWARE = "siteline synth"
