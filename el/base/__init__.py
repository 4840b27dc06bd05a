"""The flight code's base layer (docs/architecture.md section 1.1)."""
