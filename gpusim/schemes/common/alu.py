"""ALU instruction counts of the schemes' thread programs (OpPlan.compute), from what each step does.

Counts are scalar instructions of one thread, as a GPU compiler would emit
them for the step; the timing model issues them at the SM's lanes, a warp
lasting as long as its busiest thread. They describe the schemes' programs,
not a GPU: the same counts serve every preset.
"""

from __future__ import annotations

import numpy as np

#: one compare-exchange of a register sort on (depth, payload) pairs: compare, two selects per register
COMPARE_EXCHANGE = 5
#: compositing one fragment front to back: 4 multiply-adds of the colour, the transmittance update, its test
COMPOSITE = 6
#: unpacking an 8-bit RGBA colour from a 32-bit word: 4 shifts/masks and 4 conversions
UNPACK_RGBA8 = 8
#: packing depth and colour into one word (FreePipe section 4.1.2): scale, convert, shift, mask, or
PACK_DEPTH_COLOUR = 6
#: a weight or blend factor evaluation (WBOIT's weight, an alpha blend): a few multiply-adds
WEIGHT = 6
#: count leading zeros of the four colour channels and the section's Length-table entry (TFSS, seed 003)
LEADING_ZEROS = 10
#: one step of LucidRaster's bitonic sort of single-word keys (22 or 18 depth bits over the index), as each lane
#: of the pair does it (``swap`` in nadult/lucid data/shaders/shared/raster.glsl): a subgroup shuffle-xor, the
#: compare, its test against the lane's direction bit, a select
KEY_COMPARE_EXCHANGE = 4
#: re-joining FreePipe's two 12-bit colour halves (seed 000 section 4.1.2): 2 masks, a shift, an or; then
#: 3 channel extracts and 3 conversions of the 24-bit RGB
UNPACK_SPLIT_RGB24 = 10
#: premultiplying the output colour by a weight or alpha: 3 multiplies
PREMULTIPLY = 3
#: WBOIT's resolve of one pixel: clamp accum.a (min, max), its reciprocal, 3 multiplies of accum.rgb, 1 - revealage
WBOIT_RESOLVE = 7
#: a depth-peeling fragment against the previous pass's depth: a compare and the discard it decides
PEEL_TEST = 2
#: a dual-depth-peeling fragment against the previous min and max: 2 compares (front, back), 2 selects of outputs
DUAL_PEEL_TEST = 4
#: an R-buffer fragment against its pixel's second z: a compare and the branch (blend and leave, or write back)
RECIRCULATE_TEST = 2
#: one pair of a pixel's fragments in Eq. 4's weight factors (seed 003 Figure 2-6): compare the depths, select
#: which weight takes the other's (1 - a) (2 selects), 2 multiplies
WEIGHT_FACTOR_PAIR = 5
#: reading a leading-0s-eliminated colour back (seed 003 section 3.3): the Length-table field's shift and mask,
#: then per RGB channel its bit offset (an add), a shift and a mask
LEADING_ZEROS_DECODE = 11

#: WBOIT's weight function per fragment (McGuire & Bavoil 2013 eq. 7-10, as gpusim.schemes.blending), times
#: alpha; |z| from window depth d is near far / (far - d (far - near)): an fma, a reciprocal, a multiply (3)
WBOIT_WEIGHT: dict[str, int] = {
    "constant": 0,        # w = a: nothing to evaluate
    "eq10": WEIGHT,       # 1 - d, its square and cube (2), x 3e3, max, x a
    "eq7": 3 + 12,        # |z|; z/5 and fma((z/5)^2, +1e-5); z/200 and ^2, ^4, ^6 (4); add; rcp; x 10; clamp (2); x a
    "eq8": 3 + 13,        # |z|; z/10, ^2, fma(^3, +1e-5) (3); z/200, ^2, ^4, ^6 (4); add; rcp; x 10; clamp (2); x a
    "eq9": 3 + 8,         # |z|; z/200, ^2, fma(^4, +1e-5) (3); rcp; x 0.03; clamp (2); x a
}


def compare_exchange(payload_bytes: int) -> int:
    """Instructions of one compare-exchange of (depth, payload) entries whose payload takes ``payload_bytes``
    (in 32-bit registers): the compare, then for each of the two outputs a select per register.
    ``COMPARE_EXCHANGE`` is the one-register case (a packed rgba8 colour): an RGBA32F entry costs 11."""
    return 1 + 2 * (1 + -(-int(payload_bytes) // 4))


def insertion_compares(length: np.ndarray, inversions: np.ndarray | None = None) -> np.ndarray:
    """Compares of an insertion sort per list: ``length - 1`` plus its inversions (all of them, the worst
    case, when ``inversions`` is None: n (n - 1) / 2)."""
    length = np.asarray(length, np.int64)
    if inversions is None:
        return length * (length - 1) // 2
    return np.maximum(length - 1, 0) + np.asarray(inversions, np.int64)


def bitonic_compares(length: np.ndarray) -> np.ndarray:
    """Compare-exchanges of a bitonic network per list: on the next power of two m >= n,
    (m / 2) log2(m) (log2(m) + 1) / 2; none for a list of 0 or 1."""
    length = np.asarray(length, np.int64)
    m = np.ones_like(length)
    big = length > 1
    m[big] = 1 << np.ceil(np.log2(length[big])).astype(np.int64)
    log = np.log2(m).astype(np.int64)
    return (m // 2) * log * (log + 1) // 2


def sort_compares(length: np.ndarray, method: str) -> np.ndarray:
    """Compare-exchanges per list of ``length`` elements sorted in registers by ``method`` (insertion sort at
    its worst case: lists loaded in arrival order are unsorted in general)."""
    if method == "bitonic":
        return bitonic_compares(length)
    if method == "insertion":
        return insertion_compares(length)
    raise ValueError(f"unknown sort {method!r} (valid: insertion, bitonic)")


def weight_factor_work(fragments: np.ndarray) -> np.ndarray:
    """Instructions of Eq. 2-4's read-out of a pixel with ``fragments`` visible fragments (seed 003 Figure 2-6;
    Weight-Factor and TFSS): each pair compared once (``WEIGHT_FACTOR_PAIR``), each fragment blended with its
    weight (``COMPOSITE``)."""
    m = np.asarray(fragments, np.int64)
    return m * (m - 1) // 2 * WEIGHT_FACTOR_PAIR + m * COMPOSITE

#: a shared-memory atomic add (LucidRaster's per-bin and per-row counters in a workgroup): the counter's
#: address (2), the atomic itself (1), the test of its result (1)
SHARED_ATOMIC = 4

# LucidRaster (seed 002), counted from its public shaders (nadult/lucid, data/shaders/; shader and function
# named with each count). One instruction per scalar operation a compiler emits for the GLSL: an fma, a
# compare, a select, a shift or mask, a conversion, a transcendental (rcp, rsqrt, log2, exp2; pow is log2, a
# multiply and exp2), a subgroup shuffle or vote, a shared-memory load or store; a vector operation counts per
# component, a dot product of 3 as 3. Global loads, stores and atomics are the plan's memory operations (their
# address arithmetic is the timing model's core.instructions_per_op); barriers are not counted.

#: a scalar load that an SM's L1 serves from the line an earlier load of the same span brought in (the 4
#: indices of a quad, the 3 floats of a vertex, the two halves of a triangle's scanline or barycentric
#: uvec4[2]): the timing model has no L1, so the span is one load and each further load its issue slot here
L1_SPAN_LOADS = 1
#: quad_setup.glsl, main loop and processInputQuad up to the culling tests: the chunk's quad count and offsets
#: from shared memory, the 4 indices offset (11); the degenerate tests, 6 index compares and 4 ors, 6 vec3
#: compares of the loaded vertices (3 compares and 2 ands each) and 4 ors (44)
SETUP_QUAD_INPUT = 55
#: processInputQuad's back-face test (culling on): 4 vertices minus the frustum origin (12), two cross
#: products of edges (9 each), two volumes (3 each), 2 compares and 2 ors, the test (42)
SETUP_BACKFACE = 42
#: processInputQuad: the culling flags (3), 4 vertices by the view-projection matrix (12 fmas each), 4
#: vertexClipMask (6 compares, 6 selects, 5 ors each), their and/or combination (16) and the frustum test (1)
SETUP_PROJECT = 3 + 48 + 68 + 17
#: processInputQuad after the frustum test: 4 reciprocals of w, the near-plane test, x and y divided by w (8),
#: two computeAABB (8 each), to screen (8 fmas) and joined (4), the between-samples test (12), 3 clamps of
#: 4 values (add, min, max: 36), the bin AABB (8) and encodeAABB28 with the culling bits (12), its size class (7)
SETUP_AABB = 4 + 1 + 8 + 16 + 12 + 12 + 36 + 20 + 7
#: processInputQuad's compaction: the shared counter (SHARED_ATOMIC and its index, 6), the large quads'
#: reversed slot (3), the shared stores of the AABB, the two triangles' y ranges (packed: 8) and the indices
#: (14 with their addresses)
SETUP_COMPACT = 23
#: quad_setup.glsl main, every lane of a chunk between its phases: the chunk's small and large counts, its
#: triangle count, instance id and flags from shared memory
SETUP_CHUNK_LANE = 6
#: quad_setup.glsl main, lane 0 of a chunk: the instance record and offsets, the visible counts' clamp, the
#: last chunk's binning dispatch count (its divisions and clamp)
SETUP_CHUNK_LEAD = 25
#: the triangle loop of quad_setup.glsl main and addVisibleTri up to its culling flag: loop, quad slot (small or
#: large, reversed), the flag from the shared AABB word
SETUP_TRI_ENTRY = 12
#: addVisibleTri after the flag (the quad's indices from shared memory, 9 subtracts of the shared origin, the
#: y range: 26) and storeTri: normal (12), its length and scale (7), encodeNormalUint (13, with its flag test
#: 15), the barycentric edges and parameters (39), their projection on the frustum (18), the depth equation
#: (13), the three scanline edge normals (27), their orientation (13), projection (27), reciprocals and scan
#: base and step (9), the x and y sign bits (17) and the scan start (6)
SETUP_TRI = 26 + 197
#: addVisibleQuad and storeQuad: the quad's slot, the shared AABB and indices, the culling flags, the tests of
#: the instance flags for vertex colours, normals and texture coordinates (none in the look-alikes)
SETUP_QUAD_STORE = 16

#: bin_counter.glsl / bin_dispatcher.glsl: one step of a lane's loop over the per-bin counters in shared
#: memory (a store or load and the loop)
BIN_CLEAR_STEP = 2
#: bin_counter.glsl countSmallQuads / countLargeTris, lane 0 per batch acquired: the batch's global atomic,
#: its test, the batch number, the linked list of the workgroup's batches (shared bookkeeping)
BIN_BATCH = 12
#: the same loops, every lane per batch: the shared batch offset, its test and the loop
BIN_BATCH_LANE = 4
#: countSmallQuadBins / dispatchQuad per small quad: its index in the batch (3), decodeAABB28 (7), the nested
#: loop's set-up (2); dispatchQuad adds the culling flags (2)
BIN_QUAD = 12
#: one bin of a small quad's AABB: the bin index (an IMAD), the shared atomic (SHARED_ATOMIC), the loop (2)
BIN_QUAD_BIN = 3 + SHARED_ATOMIC
#: copying a workgroup's shared counters out (countSmallQuads' end), per bin and lane: the shared load, the
#: test of the count, the loop (the store and the global atomic are memory operations)
BIN_COPY_STEP = 4
#: countLargeTriBins / dispatchLargeTri per large triangle: its quad and half (3), the culling flag (3),
#: decodeAABB28 (7) and loadScanlineParamsBin (45: sign bits, the trivial-reject offsets, the start, the
#: step scaled to bins)
BIN_TRI = 58
#: countLargeTriBins per bin row: scanlineStep (16), the clamp to the AABB (2), the test, the two shared
#: atomics (8) and their addresses and test (3), the loop (2)
BIN_TRI_ROW = 32
#: accumulateLargeTriCountsAcrossRows, per counter a lane takes: the shared load, subgroupInclusiveAddFast (5
#: shuffle-compare-select-add steps: 20), the row carry's add and shuffle, the store and the loop
BIN_ROW_PREFIX = 25
#: dispatchSmallQuads / dispatchLargeTris, per bin and lane: the saved count's test, the shared store of the
#: reserved offset, the loop (the load and the atomic on the global offsets are memory operations)
BIN_OFFSET_STEP = 5
#: dispatchLargeTriBalanced per bin row of a subgroup: the votes (4), scanlineStep and clamp (18), the row's
#: bins (2), subgroupInclusiveAddFast (20) and the total's shuffle (2), the segment size and an integer
#: division by it (14), the segment owners' shared stores (6), the first source lane and offsets (12)
BIN_BALANCE_ROW = 78
#: dispatchLargeTriBalanced's inner loop, per entry a lane writes: the vote (2), 3 shuffles, 3 tests, the
#: shared atomic (SHARED_ATOMIC), the offset's wrap (4), the count (1)
BIN_BALANCE_ENTRY = 17
#: bin_categorizer.glsl computeOffsets, per bin and lane: subgroupInclusiveAddFast (20), the exclusive value's
#: shared store (2), the subgroup total's conditional store (3), the loop (2)
CATEGORIZE_SCAN = 27
#: computeOffsets' scans of the subgroup totals (lanes below bins / 32, then bins / 1024) and their fix-up
CATEGORIZE_TOTALS = 22 + 24 + 4
#: computeOffsets' last loop, per bin and lane: the shared loads, the subgroup offset's index and test, the add
CATEGORIZE_OFFSET = 8
#: categorizeBins, per bin: the triangle count (quads count twice: an IMAD), its class (3), the level's
#: shared atomic (SHARED_ATOMIC) and index (1), the loop (2)
CATEGORIZE_BIN = 11

#: raster.glsl loadNextBin, lane 0 per bin: the level's global atomic and its test, the bin's position (a
#: division by a constant and an IMAD, 2 shifts), the shared stores of its counts and offsets
RASTER_BIN_FETCH = 14
#: every lane per bin: the bin loop's test of the shared bin id, the counters' clearing (rasterBin's start)
RASTER_BIN_LANE = 4
#: processQuads per quad entry and lane (each of the 2 lanes of a quad takes one triangle): the loop, the
#: half, the index mask, the culling flag's shift, mask and test
ROW_QUAD_ENTRY = 8
#: processQuads per large-triangle entry: the loop and the index
ROW_TRI_ENTRY = 3
#: generateRowTris before its row loop: offsets (4), the first and last row from the y range (clamps: 10),
#: the start (4) and loadScanlineParamsRow (sign bits 6, the scan start 6, infinities 6)
ROW_TRI_SETUP = 36
#: rasterBinStep: 4 SCAN_STEPs (3 max, a conversion, 3 min, a conversion and subtract, the empty test and 2
#: selects, 6 adds: 18 each), 4 BX_MASK_ROWs (6 each) and their ors (3), the min and max bit fields (12)
RASTER_BIN_STEP = 4 * 18 + 4 * 6 + 3 + 12
#: raster_low.glsl generateRowTris per block-row of its y range: two rasterBinSteps (8 pixel rows), the
#: columns' or and test, the loop
ROW_STEP_LOW = 2 * RASTER_BIN_STEP + 4
#: raster_low.glsl generateRowTris per block-row a triangle covers: the row's shared atomic (SHARED_ATOMIC),
#: the offset (2), the packing of pixel intervals, columns and triangle index into 2 x 64 bits (10)
ROW_STORE_LOW = SHARED_ATOMIC + 2 + 10
#: raster_high.glsl generateRowTris per half-block row of its y range: one rasterBinStep, the test, the loop
ROW_STEP_HIGH = RASTER_BIN_STEP + 3
#: raster_high.glsl generateRowTris per half-block row a triangle covers: findLSB and findMSB of the
#: columns (3), the two shared atomics of the column counts (8 and their test), the row's shared atomic
#: (SHARED_ATOMIC) and overflow test, the offset (2) and the packing (8)
ROW_STORE_HIGH = 3 + 1 + 8 + 1 + SHARED_ATOMIC + 1 + 2 + 8
#: raster_low.glsl generateBlocks' first loop, per tri-block-row of the block's row and lane: the loop and
#: the column bit's test
BLOCK_ROW_TEST = 4
#: ... and per tri-block-row that covers the block: the block's shared atomic (SHARED_ATOMIC), the limit's
#: compare, the shared store of the row index
BLOCK_ROW_HIT = SHARED_ATOMIC + 3
#: generateBlocks per block and lane: its row, column and offsets, the limit's vote, the shared count, the
#: block's position
BLOCK_SETUP = 15
#: rasterHalfBlockCentroid: 4 row minima (shift, mask, subtract, max: 15) and maxima (15), the counts (8),
#: the centroid's x and y sums (20), the fragment count (3), the sums (6)
HALF_BLOCK_CENTROID = 67
#: rasterHalfBlockBits: the row minima and maxima and counts as in the centroid (38), the fragment count (2),
#: the packed minima (7) and counts (7)
HALF_BLOCK_BITS = 54
#: generateBlocks' second loop per tri-block: the shared row index (2), the triangle index (4), two
#: rasterHalfBlockCentroids, the count (1), the centroid (4), rasterBlockDepth (2 fmas, an add, rsqrt,
#: saturate, a multiply, a conversion: 7), the packed fragment counts (2), the key's shared store (2)
TRI_BLOCK_DEPTH = 2 + 4 + 2 * HALF_BLOCK_CENTROID + 1 + 4 + 7 + 2 + 2
#: generateBlocks after the second loop, per lane: subgroupInclusiveAddFast32 (20), the last lane's two packed
#: shared stores of the half-blocks' counts (9)
BLOCK_SCAN = 29
#: generateBlocks' third loop per tri-block: the loop (2), the sorted index (2), the triangle bits (5), two
#: rasterHalfBlockBits, the packed counts (2), subgroupInclusiveAddFast32 (20), the offsets and the shuffle
#: of the running base (9), the packing of the two tri-half-blocks (4)
TRI_HALF_BLOCKS = 2 + 2 + 5 + 2 * HALF_BLOCK_BITS + 2 + 20 + 9 + 4
#: raster_high.glsl computeRBlockGroups: lanes below 32, the column prefix by shuffles (9), the clearing
#: store, subgroupMax_ over 32 lanes (10), ...; lane 0 adds the sort's rcount and the group size (20)
RBLOCK_GROUPS = 22
RBLOCK_GROUPS_LEAD = 20
#: generateRBlocks per half-block and lane of its group: the group's size, shift, thread, half-block,
#: position, counts and offsets from shared memory
RBLOCK_SETUP = 16
#: generateRBlocks' tri-half-block depth per entry: the shared row index (2), the triangle index (4),
#: rasterHalfBlockCentroid, the centroid (4), rasterBlockDepth (7), the key's shared store (3)
RBLOCK_DEPTH = 2 + 4 + HALF_BLOCK_CENTROID + 4 + 7 + 3
#: generateRBlocks' count per entry: the shared index (2), rasterHalfBlockNumFrags (40),
#: subgroupInclusiveAddFast32 (20), the packed shared store (5)
RBLOCK_COUNT = 2 + 40 + 20 + 5
#: generateRBlocks' prefix sum across a half-block's subgroups, lanes below 64: indices (8), 4 partial sums
#: (20), their sum (3), up to 5 shuffle steps (15), 4 shared stores (8) and the total's (2)
RBLOCK_PREFIX = 56
#: generateRBlocks' last loop per entry: the shared entry and its offset (8), the triangle bits (5),
#: rasterHalfBlockBits, the segment fields and packing (6)
RBLOCK_STORE = 8 + 5 + HALF_BLOCK_BITS + 6

#: raster.glsl unpackSamples per segment: the overflow copy (2 shared accesses), the control word's fields (7),
#: the path's test, the control word's update (3)
UNPACK_SEGMENT = 13
#: unpackSamples' row path (8 tri-half-blocks an iteration, a lane per row) per iteration: the loop, the
#: segment test (3), the row's interval (3), 2 shuffles with masks and adds (6), the offsets, pixel id and
#: value (9)
UNPACK_ROWS = 23
#: ... and per sample of the lane's row: the shared store, the increments, the test
UNPACK_ROW_SAMPLE = 3
#: unpackSamples' bit path (high triangle density: a tri-half-block per lane) per iteration: the loop, the
#: segment test, the offsets (7), blockRowsToBits (27), the loop test
UNPACK_BITS = 35
#: ... and per sample: findLSB, the bit's clearing (2), the shared store of pixel and triangle, the increment
UNPACK_BIT_SAMPLE = 5
#: shadeAndReduceSamples per 32-sample step and lane: the loop, the shared load of the sample and clearing
#: store, the sample's index and test, the pixel bit, the shared atomicOr, the shared load of the pixel's
#: bit mask, bitCount
SHADE_STEP = 16
#: shading.glsl shadeSample for the look-alikes (an instance colour, per-triangle normals; no texture, no
#: vertex attributes): the pixel position (6), the triangle's flags and id (2), its depth, the reciprocal and
#: barycentrics (11), the flag tests (10), decodeRGBA8 of the instance colour and its select (16),
#: decodeNormalUint (14), the light value (5), finalShading: SRGBToLinear (3 channels of compare, multiply,
#: add, multiply, log2, multiply, exp2, select: 24), the ambient and sun light (9), their product with the
#: colour (6), linearToSRGB (21), the saturate (3); encodeRGBA8 (14)
SHADE_SAMPLE = 6 + 2 + 11 + 10 + 16 + 14 + 5 + 24 + 9 + 6 + 21 + 3 + 14
#: reduceSample, one iteration of its loop (each lane takes the next sample of its pixel; the subgroup loops
#: while any lane has one): the vote, findLSB and the bit's clearing (5), 2 shuffles, the count's test and
#: decrement (3), the depth test against the newest entry (2), the test of the oldest colour (2),
#: decodeRGBA8 (15), the front-to-back blend (7); plus ``depth_filter`` moves each of the depths and colours
#: (``reduce_step``)
REDUCE_STEP = 2 + 1 + 2 + 2 + 3 + 2 + 2 + 15 + 7
#: the alpha threshold's vote in each iteration (ALPHA_THRESHOLD: subgroupAll of the transmittance test)
REDUCE_THRESHOLD = 3
#: reduceSample's insertion of a sample nearer than a filter entry: per entry it moves past, the compare, the
#: branch and the swap of depth and colour (6 moves)
REDUCE_SWAP = 8
#: finishReduceSamples and outputPixel per lane: the background (3 fmas), saturate (3), the pixel's position
#: (4); plus per filter entry its test (2) and, where some lane's entry holds a sample, decodeRGBA8 and the
#: blend (22) (``finish_work``)
FINISH = 10
FINISH_ENTRY_TEST = 2
FINISH_ENTRY_BLEND = 22
#: initReduceSamples (2 per filter entry, 4) and initUnpackSamples with the half-block's counts (12)
HALF_BLOCK_START = 16
#: updateStats: the shared counts' fields and 2 shared atomics
RASTER_STATS = 11


def reduce_step(depth_filter: int, alpha_threshold: bool = False) -> int:
    """Instructions of one iteration of reduceSample's loop with a depth filter of ``depth_filter`` entries
    (RC_DEPTH_SIZE = RC_COLOR_SIZE): ``REDUCE_STEP`` plus the shift of the depths and of the colours by one
    entry (``depth_filter`` moves each), plus the alpha threshold's vote."""
    return REDUCE_STEP + 2 * int(depth_filter) + (REDUCE_THRESHOLD if alpha_threshold else 0)


def finish_work(depth_filter: int, filled: np.ndarray) -> np.ndarray:
    """finishReduceSamples' instructions per lane: ``filled`` entries (the most any lane of the half-block
    holds, at most the filter's size) blended, every entry tested."""
    filled = np.minimum(np.asarray(filled, np.int64), int(depth_filter))
    return FINISH + FINISH_ENTRY_TEST * int(depth_filter) + FINISH_ENTRY_BLEND * filled


def lucid_sort_work(count: np.ndarray, rcount: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Instructions per lane of LucidRaster's sortBuffer (shared/raster.glsl): ``count`` keys padded to
    ``rcount`` (a power of two >= ``group``) with 0xffffffff, sorted by ``group`` lanes (32: a low-rasterizer
    subgroup; 32 x 2^k: a high-rasterizer half-block's group):

    * the padding stores (2 per lane step) and the lane's 6 direction bits (12);
    * the in-register stages K = 2 .. 16 (32 .. with 64+ lanes: 15 swaps): per element a lane holds, a shared
      load, ``KEY_COMPARE_EXCHANGE`` per swap, the store and the loop;
    * per merge stage k from 32 (64) to rcount: the steps j = k/2 .. 32 through shared memory, rcount / (2
      group) pairs per lane each (index, 2 loads, the compare and conditional exchange of 2 stores: 14), then
      the register steps j = 16 .. 1 per element (a load, 5 swaps, the bit, the store, the loop: 25)."""
    count = np.asarray(count, np.int64)
    rcount = np.asarray(rcount, np.int64)
    group = np.asarray(group, np.int64)
    per_lane = rcount // group
    pairs = np.maximum(rcount // (2 * group), 1)
    first = np.where(group >= 64, 15, 10)
    log_r = np.round(np.log2(np.maximum(rcount, 1))).astype(np.int64)
    start = np.where(group >= 64, 6, 5)
    stages = np.maximum(log_r - start + 1, 0)                     # merge stages k = 2^start .. rcount
    shared_steps = np.maximum(stages * (start - 5) + stages * (stages - 1) // 2, 0)   # sum of (m - 5)
    pad = -(-(rcount - count) // group)
    work = (2 * pad + 12 + per_lane * (4 + KEY_COMPARE_EXCHANGE * first)
            + stages * per_lane * (4 + 5 * KEY_COMPARE_EXCHANGE + 1) + shared_steps * pairs * 14)
    return np.where(count > 1, work, 0)

#: a fragment's bucket or histogram bin in its pixel's depth range (bucket depth peeling, Liu et al. 2009):
#: z - near, the reciprocal of far - near, two multiplies (by it and by the bucket count), a convert, a clamp
BUCKET_INDEX = 6
#: one 32-bit output channel of a fragment routed over MRTs: compare the channel's number with the bucket's,
#: select the depth (or the histogram bit) or the empty value
CHANNEL_SELECT = 2
#: one 32-bit word of an occupancy histogram read back: mask the bins below the fragment's, count the bits, add
POPCOUNT_WORD = 3
#: the adaptive bucket of an occupied bin: its rank times the buckets over the occupied bins (a multiply, a
#: reciprocal, a multiply, a convert)
EQUALISE = 4
#: the composite's test of one bucket for the empty value (a compare and the branch around its compositing)
BUCKET_SCAN = 2

#: an MLAB fragment's output (Salvi & Vaidyanathan 2014): its colour premultiplied by alpha (3 multiplies) and
#: its transmittance 1 - a (1)
MLAB_FRAGMENT = PREMULTIPLY + 1
#: MLAB's merge of the two farthest of its layers + 1 entries: rgb + rgb' T (3 fmas), T T' (1), the test whether
#: the last entry is occupied and a select of each of the 4 merged values
MLAB_MERGE = 3 + 1 + 1 + 4

#: moment-based OIT's pass 1 per fragment (Münstermann et al. 2018): alpha clamp (a min), 1 - a, the logarithm
#: (log2 and a multiply) and the depth warp (an fma) = 5; then power moments: the powers z^2 .. z^m (m - 1
#: multiplies) and A z^j (m); trigonometric: the phase (an fma), sin and cos (2), the complex powers
#: e^(2 i phi) .. e^(m i phi) (m - 1 complex multiplies of 4) and A times 2m reals
MBOIT_GENERATE = {"power4": 5 + 3 + 4, "power6": 5 + 5 + 6, "trig4": 5 + 1 + 2 + 3 * 4 + 8}
#: the roots of the kernel polynomial: a quadratic in its stable form (the discriminant: a multiply, an fma, a
#: clamp; its square root; the sign select (2); an add and a multiply; 2 divisions of 2); a cubic by Blinn's
#: homogeneous method (B and C (2); the Hessian's 3 terms of 2; the discriminant (3) and its root; per end of
#: the range: D-bar (3), atan2 (8), abs and / 3 (2), the scale's clamp, root and multiply (3), sin and cos (2),
#: 2 roots (3), a select (2); the middle root (9); 3 divisions of 2); a complex quartic by Ferrari (monic form:
#: a complex reciprocal (6) and 4 complex multiplies (16); the depressed coefficients (40); the resolvent by
#: Cardano: a complex square root (8), a cube root in polar form (12), 3 candidate roots of a complex division
#: (10), a size (3) and a select (2); 3 complex square roots (24) and the 4 roots (8))
MBOIT_ROOTS = {3: 3 + 1 + 2 + 2 + 4, 4: 2 + 6 + 4 + 2 * 23 + 9 + 6, 5: 6 + 16 + 40 + 8 + 12 + 3 * 15 + 24 + 8}
#: moment-based OIT's resolve per pixel: the total transmittance exp(-b_0) (a multiply and exp2), 1 - T, the
#: reciprocal of the accumulated alpha and 3 multiplies of the accumulated colour by it and by 1 - T (6)
MBOIT_RESOLVE = 2 + 1 + 1 + 6


def mboit_reconstruct(kind: str, count: int) -> int:
    """Instructions of moment-based OIT's transmittance at one fragment's depth from ``count`` moments of
    ``kind`` ("power" or "trigonometric"; gpusim.schemes.common.moments), on a k x k moment matrix (Hankel:
    k = count / 2 + 1, real; Toeplitz: k = count + 1, complex, where an fma costs 4):

    * normalise and bias the moments: a reciprocal of b_0, a multiply and an fma per real;
    * the L D L^H factorisation: an fma per product of its sums, a multiply per entry of L, a reciprocal per
      pivot;
    * the kernel polynomial (B c = u(x_0)): forward and backward substitution, k^2 fmas, and the powers of
      x_0 (k - 1 multiplies);
    * its roots (``MBOIT_ROOTS``);
    * a Christoffel weight per support point (k of them): the powers of the point, a forward substitution,
      k squared sizes over D (an fma each) and a reciprocal; trigonometric moments also take each point's
      angle (atan2, 8) to compare;
    * per root a compare and a select-add (trigonometric: also the wrapping zone's ramp, an fma, a clamp and a
      max); then b_0 times the share, exp2 and saturate (4)."""
    complex_ = kind == "trigonometric"
    k = count // 2 + 1 if not complex_ else count + 1
    op = 4 if complex_ else 1
    reals = count * (2 if complex_ else 1)
    normalise = 1 + 2 * reals
    ldl = op * (sum(j for j in range(k)) + sum((k - 1 - j) * (j + 1) for j in range(k))) + k
    kernel = op * (k * k + k - 1)
    weight = op * ((k - 1) + k * (k - 1) // 2) + 2 * k + 1 + (8 if complex_ else 0)
    return normalise + ldl + kernel + MBOIT_ROOTS[k] + k * weight + (5 if complex_ else 2) * (k - 1) + 4
