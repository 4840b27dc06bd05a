"""The flight code's geometry layer (docs/architecture.md section 1.1)."""
