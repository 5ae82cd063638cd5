"""Helpers the scheme modules share; no scheme is registered here.

The scheme modules live in gpusim.schemes (one per scheme); what more than one
of them needs lives here, one idea per module:

================ ==============================================================
arrays           fixed arrays of entries per pixel: layouts, entry indices,
                 pixel keys, ranks within runs
depth_filter     a per-pixel fixed-capacity priority queue that emits the
                 nearest entry when full (k-buffer, LucidRaster's depth filter)
depthkey         depths as ordered 32-bit integers; FreePipe's depth + colour
                 packing
early_z          phases 1 and 2 of the seed-003 transparent-storage pipelines
                 (TFSS, R-buffer, Weight-Factor)
fold             per-pixel sequential updates in submission order (ROP
                 blending), vectorised over pixels
groups           per-pixel views of a trace: arrival order and depth order
kbuffer_entries  the k-buffer's entry formats (depth + colour, RGBZ, Z-only):
                 bytes, MRT texels, the image of what they store
kbuffer_replay   the k-buffer program replayed in event order (what RMW
                 hazards do to the image)
leading_zeros    leading-0s elimination of stored colour (seed 003)
lucid_bins       LucidRaster's screen hierarchy: bins, block-rows, blocks,
                 half-blocks
reorder          object-space reordering of a trace before a scheme sees it
                 (centroid sort, batches)
sections         chained per-pixel sections (TFSS's T-buffer, Weight-Factor's
                 M-buffer)
sorting          per-pixel insertion and bitonic sorts of a resolve pass
storage          storage formats of a stored colour and their sizes
weights          weight-factor compositing (Eq. 2-4) and n-bit colours
================ ==============================================================
"""
