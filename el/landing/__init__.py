"""The flight code's landing layer (docs/architecture.md section 1.1)."""
