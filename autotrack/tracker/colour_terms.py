"""Our own colour feature, 'lab11': a soft assignment of each sRGB colour to the 11 English basic
colour terms in CIELAB, with prototypes from the xkcd colour survey (see `COLOUR_PROTOTYPES`),
projected onto the 10-D subspace orthogonal to the all-ones vector. Built from colour science
alone, never from the published Color Names table; `features.lab11_table` keeps the table of
every RGB bin in the user cache.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

COLOUR_TABLE_ROWS = 32 * 32 * 32
"""Rows of a colour lookup table: one per RGB bin R//8 + 32 (G//8) + 1024 (B//8)."""


COLOUR_TERMS = (
    "black", "blue", "brown", "grey", "green", "orange", "pink", "purple", "red", "white", "yellow",
)  # fmt: skip
"""The 11 English basic colour terms (Berlin & Kay 1969), in the Color Names table's order."""

COLOUR_PROTOTYPES: dict[str, tuple[str, ...]] = {
    "black": ("000000",),
    "blue": ("0343df", "95d0fc", "00035b"),
    "brown": ("653700", "ad8150", "341c02"),
    "grey": ("929591", "d8dcd6", "363737"),
    "green": ("15b01a", "96f97b", "033500"),
    "orange": ("f97306", "fdaa48", "c65102"),
    "pink": ("ff81c0", "ffd1df", "cb416b"),
    "purple": ("7e1e9c", "bf77f6", "35063e"),
    "red": ("e50000", "ff474c", "840000"),
    "white": ("ffffff",),
    "yellow": ("ffff14", "fffe7a", "d5b60a"),
}
"""sRGB prototypes per term: the colours the xkcd colour survey (R. Munroe, 2010; about 200,000
participants naming random monitor colours; results public domain) gives for the names 'T',
'light T' and 'dark T' of each basic term T ('black' and 'white' have no variants). Several
prototypes per term cover its lightness range, which a single focal colour does not (dark red
would otherwise fall to brown, navy to purple)."""

LAB11_SIGMA = 12.0
"""Width (CIELAB Delta E*ab) of the Gaussian kernel on the distance to a term's nearest prototype.
The median distance from a prototype to the nearest prototype of another term is 32; at sigma 12
such a neighbour keeps a weight exp(-32^2 / (2 * 12^2)) ~ 0.03, so assignments are soft between
neighbouring terms and close to one-hot at a prototype."""

_D65_WHITE = np.array([0.95047, 1.0, 1.08883])
_SRGB_TO_XYZ = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ]
)  # IEC 61966-2-1 (sRGB) primaries, D65


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of sRGB values on the 0..255 scale; (..., 3) -> (..., 3) float64."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)  # IEC 61966-2-1
    xyz = linear @ _SRGB_TO_XYZ.T / _D65_WHITE
    delta = 6.0 / 29.0
    f = np.where(xyz > delta**3, np.cbrt(xyz), xyz / (3 * delta**2) + 4.0 / 29.0)  # CIE 15
    return np.stack(
        [
            116.0 * f[..., 1] - 16.0,
            500.0 * (f[..., 0] - f[..., 1]),
            200.0 * (f[..., 1] - f[..., 2]),
        ],
        axis=-1,
    )


@lru_cache(maxsize=1)
def _prototype_lab() -> tuple[np.ndarray, np.ndarray]:
    """(index of each term's first prototype, CIELAB of the prototypes grouped by term)."""
    first, colours = [], []
    for term in COLOUR_TERMS:
        first.append(len(colours))
        colours.extend(
            [int(code[i : i + 2], 16) for i in (0, 2, 4)] for code in COLOUR_PROTOTYPES[term]
        )
    return np.array(first), srgb_to_lab(np.array(colours, dtype=np.float64))


def colour_term_probabilities(rgb: np.ndarray, sigma: float = LAB11_SIGMA) -> np.ndarray:
    """Soft assignment of sRGB colours (..., 3), 0..255 scale, to `COLOUR_TERMS` -> (..., 11).

    p_t ∝ exp(-d_t^2 / (2 sigma^2)), d_t the CIELAB distance to term t's nearest prototype.
    """
    first, prototypes = _prototype_lab()
    lab = srgb_to_lab(rgb)
    squared = (
        (lab**2).sum(axis=-1, keepdims=True)
        + (prototypes**2).sum(axis=-1)
        - 2.0 * lab @ prototypes.T
    )
    nearest = np.minimum.reduceat(np.maximum(squared, 0.0), first, axis=-1)
    logits = -nearest / (2.0 * sigma**2)
    logits -= logits.max(axis=-1, keepdims=True)
    weights = np.exp(logits)
    return weights / weights.sum(axis=-1, keepdims=True)


@lru_cache(maxsize=1)
def lab11_projection() -> np.ndarray:
    """(10, 11) orthonormal rows spanning the complement of the all-ones vector (Helmert).

    The 11 probabilities sum to one, so projecting onto this basis loses nothing:
    p = projection.T @ feature + 1/11.

    scipy.linalg is imported here, on first use, not by every tracker process at start-up.
    """
    import scipy.linalg

    basis = scipy.linalg.helmert(len(COLOUR_TERMS))
    basis.flags.writeable = False
    return basis


def build_lab11_table() -> np.ndarray:
    """The 'lab11' feature of every 8 x 8 x 8 RGB bin, rows indexed like the Color Names table.

    Evaluated at the bin centres (8 i + 3.5); float32 (32768, 10).
    """
    index = np.arange(COLOUR_TABLE_ROWS)
    centres = np.stack([index % 32, (index // 32) % 32, index // 1024], axis=-1) * 8.0 + 3.5
    features = colour_term_probabilities(centres) @ lab11_projection().T
    return np.ascontiguousarray(features, dtype=np.float32)
