"""After a run: band widths and profiles, figures."""
