"""The results store (SQLAlchemy), its records and schema, and the shipped results."""
