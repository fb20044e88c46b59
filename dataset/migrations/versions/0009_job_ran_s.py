"""jobs.ran_s: the seconds a job's earlier attempts ran

Revision ID: 0009
Revises: 0008

One new column, 0 for every existing job: a retried job (a resumed run's) keeps the time its
attempts before the current one ran, so that "took" counts them all.
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("ran_s", sa.Double(), server_default="0", nullable=False))


def downgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.drop_column("ran_s")
