"""One module per physics term. Every element function is a `@ti.func` with explicit arguments
that returns its energy or force and the exact derivatives the Newton Jacobian needs."""
