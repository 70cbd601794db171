"""Shared array type aliases (jaxtyping)."""

from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

Scalar = Float[Array, ""]
Vector3 = Float[Array, "3"]
Matrix3 = Float[Array, "3 3"]
State6 = Float[Array, "6"]
Covariance6 = Float[Array, "6 6"]

__all__ = [
    "Array",
    "Bool",
    "Float",
    "Int",
    "PRNGKeyArray",
    "Scalar",
    "Vector3",
    "Matrix3",
    "State6",
    "Covariance6",
]
