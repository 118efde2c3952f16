"""The Blender helpers: mesh I/O, the operator base, object names, properties, the guide, version guards."""
