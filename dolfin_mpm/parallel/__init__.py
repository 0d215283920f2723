"""Particles on DOLFINx's partition: global ids, migration, partitions that balance particles, halos."""
