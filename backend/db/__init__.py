"""Database: SQLAlchemy 2 models, engine and sessions, migrations."""
