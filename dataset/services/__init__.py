"""Services: the operations the web app, the CLI and the workers share, over a SQLAlchemy session."""
