"""Material and damping parameters of the tongue model."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic tissue with Rayleigh damping.

    Defaults are the paper's (§4, after Gérard et al. and Vogt et al.):
    young : Young's modulus, Pa.
    poisson : Poisson's ratio (dimensionless, < 0.5).
    density : kg/m³.
    alpha : mass-proportional Rayleigh damping, 1/s.
    beta : stiffness-proportional Rayleigh damping, s.
    """

    young: float = 6912.0
    poisson: float = 0.49
    density: float = 1000.0
    alpha: float = 6.22
    beta: float = 0.11

    def __post_init__(self) -> None:
        from tonguevis.errors import ModelError

        if not self.young > 0:
            raise ModelError(f"Young's modulus must be positive, got {self.young} Pa")
        if not -1.0 < self.poisson < 0.5:
            raise ModelError(f"Poisson's ratio must lie in (-1, 0.5), got {self.poisson}")
        if not self.density > 0:
            raise ModelError(f"density must be positive, got {self.density} kg/m³")
        if self.alpha < 0 or self.beta < 0:
            raise ModelError(f"Rayleigh damping must be non-negative, got α={self.alpha}, β={self.beta}")

    def as_dict(self) -> dict[str, float]:
        return asdict(self)
