"""ccjax: JAX-accelerated, differentiable computational colour constancy."""
