//! The spectral path tracer: BVH, materials, lights, integrator, film.
