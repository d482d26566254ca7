"""Standard components: one folder per component with a manifest.yaml;
implementations arrive with the simulator."""
