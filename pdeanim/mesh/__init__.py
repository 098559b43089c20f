"""Surface mesh ingestion: reading, validating and describing triangle meshes."""
