"""What every apc node needs: robot models and their config files, parameters and their
defaults, the node runtime (executors, signals, diagnostics)."""
