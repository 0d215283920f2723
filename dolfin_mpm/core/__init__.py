"""The MPM engine on DOLFINx: grid, particles, transfers, boundary conditions and the time step."""
