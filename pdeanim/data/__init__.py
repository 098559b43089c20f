"""Sample data shipped with the package (see LICENSES.md): the demo mesh."""
