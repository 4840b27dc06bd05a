"""Training and evaluating the segmentation network (what produces the weights and the model card figures)."""
