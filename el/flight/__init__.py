"""The flight code's flight layer (docs/architecture.md section 1.1)."""
