"""What a run writes: XDMF series for ParaView and checkpoints."""
