"""TensorBoard output: posterior pair plots, losses, the composed config."""
