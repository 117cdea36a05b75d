// Placeholder: procedural meshes and point sets.
