"""The flight code's classes layer (docs/architecture.md section 1.1)."""
