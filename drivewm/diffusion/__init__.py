"""Text2World diffusion: DiT backbone (dit.py), EDM preconditioning and loss (denoiser.py), samplers."""
