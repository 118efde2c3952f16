"""The Blender helpers: object names, mesh I/O and the region, the operator base and its modal runs,
properties, the guide and the panel's parts, a bolus solid's data, labels and parts, version guards."""
