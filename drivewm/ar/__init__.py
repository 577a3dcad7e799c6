"""The autoregressive world model: a causal transformer over FSQ token sequences (docs/DESIGN.md section 5).

``config`` (shape and presets), ``tokens`` (token caches from FSQ latent caches), ``model`` (the
transformer with its KV cache), ``sampling`` (temperature / top-k / top-p, cached or not), ``train``
(the training task of drivewm.train), ``generator`` (Video2World continuation and chunked rollouts),
``evaluate`` (bits per token against the copy and unigram baselines).
"""
