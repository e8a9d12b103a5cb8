"""Generalized-α coefficients (paper eq. 35)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Scalar, ScalarLike


class GenAlphaCoefficients(eqx.Module):
    """αm, αf, γ, β from the spectral radius at infinity ρ∞ ∈ [0, 1] (eq. 35).

    With these values the scheme is second-order accurate and unconditionally
    stable for linear problems, with high-frequency dissipation set by ρ∞
    (ρ∞ = 1: none; ρ∞ = 0: asymptotic annihilation).
    """

    alpha_m: Scalar
    alpha_f: Scalar
    gamma: Scalar
    beta: Scalar

    @classmethod
    def from_rho_inf(cls, rho_inf: ScalarLike) -> "GenAlphaCoefficients":
        rho = jnp.asarray(rho_inf)  # its own precision: a float32 scheme gives float32 coefficients
        alpha_m = (2.0 * rho - 1.0) / (rho + 1.0)
        alpha_f = rho / (rho + 1.0)
        gamma = 0.5 + alpha_f - alpha_m
        beta = 0.25 * (gamma + 0.5) ** 2
        return cls(alpha_m=alpha_m, alpha_f=alpha_f, gamma=gamma, beta=beta)

    def vd_per_v(self, h: Scalar) -> Scalar:
        """dv̇̃/dṽ = (1-αm)/((1-αf) γ h), the smooth-acceleration increment per
        unit smooth-velocity increment (eq. 44b)."""
        return (1.0 - self.alpha_m) / ((1.0 - self.alpha_f) * self.gamma * h)

    def q_per_v(self, h: Scalar) -> Scalar:
        """dq̃/dṽ = h β / γ (eq. 44c)."""
        return h * self.beta / self.gamma

    def a_per_vd(self) -> Scalar:
        """da/dv̇̃ = (1-αf)/(1-αm), from the α-relation (34c)."""
        return (1.0 - self.alpha_f) / (1.0 - self.alpha_m)
