"""Training infrastructure shared by the tokenizer and diffusion stages."""
