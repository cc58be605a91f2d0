"""Localisation by tracking: camera maths (`camera`), the scene file (`scene`), PnP and the
correspondence search (`pnp`), the per-frame localiser (`localizer`) and trajectory metrics
(`trajectory`)."""
