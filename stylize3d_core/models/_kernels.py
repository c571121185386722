"""Numba kernels of the models package (imported where Numba imports): the colour map of
:class:`~stylize3d_core.models.colour_transfer.ColourTransfer` and the encoder's neighbour max at inference
(:func:`~stylize3d_core.models.encoder.neighbour_max`).

The colour map, one pass per colour: the affine L*a*b* map, the clip, and the gamut mapping's bisection of the chroma
scale, in float32 with the operations of the numpy reference (``colour_transfer._linear_rgb`` and
``gamut_map``) in the same order, so the two give the same bits. The numpy reference makes a dozen
temporaries of every chunk and runs its bisection on the out-of-gamut colours as separate array passes;
on the 1.7M points of a 1 MP photo with a bright style it took ~0.2 s of the first frame on two cores.
"""

import numba
import numpy as np

jit = numba.njit(cache=True, nogil=True)

_F32 = np.float32
_D = _F32(6.0 / 29.0)
_LOW_SLOPE = _F32(3.0 * (6.0 / 29.0) * (6.0 / 29.0))
_LOW_OFFSET = _F32(4.0 / 29.0)
_LO = _F32(-1e-4)
_HI = _F32(1.0 + 1e-4)


@jit
def _cube_or_linear(f):
    if f <= _D:
        return _LOW_SLOPE * (f - _LOW_OFFSET)
    return f * f * f


@jit
def in_gamut(L, a, b, white, m):
    """Whether L*a*b* (L, a, b) is an sRGB colour: linear sRGB within [-1e-4, 1 + 1e-4] (``gamut_map``'s test)."""
    fy = (L + _F32(16.0)) / _F32(116.0)
    x = _cube_or_linear(fy + a / _F32(500.0)) * white[0]
    y = _cube_or_linear(fy) * white[1]
    z = _cube_or_linear(fy - b / _F32(200.0)) * white[2]
    for i in range(3):
        v = x * m[i, 0] + y * m[i, 1] + z * m[i, 2]
        if v < _LO or v > _HI:
            return False
    return True


@jit
def transfer(lab, mean, gain, target, white, m, steps, a0, a1, out):
    """Rows a0..a1-1: ``(lab - mean) * gain + target``, L* clipped to [0, 100] and a*, b* to [-127, 127],
    then outside the sRGB gamut the chroma scaled by the largest of ``steps`` bisection steps that fits."""
    for r in range(a0, a1):
        L = (lab[r, 0] - mean[0]) * gain[0] + target[0]
        a = (lab[r, 1] - mean[1]) * gain[1] + target[1]
        b = (lab[r, 2] - mean[2]) * gain[2] + target[2]
        L = min(max(L, _F32(0.0)), _F32(100.0))
        a = min(max(a, _F32(-127.0)), _F32(127.0))
        b = min(max(b, _F32(-127.0)), _F32(127.0))
        if not in_gamut(L, a, b, white, m):
            lo = _F32(0.0)
            hi = _F32(1.0)
            for _ in range(steps):
                mid = (lo + hi) / _F32(2.0)
                if in_gamut(L, a * mid, b * mid, white, m):
                    lo = mid
                else:
                    hi = mid
            a = a * lo
            b = b * lo
        out[r, 0] = L
        out[r, 1] = a
        out[r, 2] = b


@jit
def neighbour_max(features, idx, r0, r1, out):
    """Rows r0..r1-1 of ``out[i, c] = max_j features[idx[i, j], c]`` (float32), the neighbours in column order
    as the running ``torch.maximum`` of the encoder's torch lines: a NaN anywhere in a row's values is
    kept (``torch.maximum`` propagates it), the same values otherwise (only the sign of a zero may differ,
    as it does between torch's own vectorised and scalar loops); no (M, k, C) values and no (M, C)
    buffers are written. False (rows left unfinished) at an index outside the features' rows."""
    k = idx.shape[1]
    n, C = features.shape
    for i in range(r0, r1):
        for j in range(k):
            if idx[i, j] < 0 or idx[i, j] >= n:
                return False  # the caller's checked lines say what is wrong
        first = idx[i, 0]
        for c in range(C):
            out[i, c] = features[first, c]
        for j in range(1, k):
            p = idx[i, j]
            for c in range(C):
                v = features[p, c]
                b = out[i, c]
                if b == b and not (v < b):  # torch.maximum: a NaN in either wins, else the larger (ties: the new)
                    out[i, c] = v
    return True
