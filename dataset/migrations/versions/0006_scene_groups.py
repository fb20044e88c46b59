"""scene groups: videos that are copies of one another (re-encoded, resized, renamed) share a group,
so no split puts one in training and another in testing

Revision ID: 0006
Revises: 0005

A plain nullable column: existing videos keep NULL, which means "a group of its own", so an
existing database upgrades without a backfill and every split it made stays as it was.

Also an index on the audit log's target, so the reason a curator rejected a sample is found for its
annotator's page without reading the whole log.
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("videos", sa.Column("scene_group", sa.Integer(), nullable=True))
    op.create_index("ix_audit_log_target", "audit_log", ["target_kind", "target_id"])


def downgrade() -> None:
    op.drop_index("ix_audit_log_target", table_name="audit_log")
    # SQLite ≥ 3.35 drops a column in place; a batch operation would recreate ``videos`` and, with
    # foreign keys on, its DROP TABLE would cascade to every frame.
    op.drop_column("videos", "scene_group")
