"""The MPM engine's parts on DOLFINx: grid, particles, locate, transfers, seeding, boundary conditions."""
