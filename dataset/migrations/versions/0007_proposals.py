"""proposals: illusions proposed by the machine for frames to annotate, and each one's fate

Revision ID: 0007
Revises: 0006

Two new tables, nothing existing changes: a scan per (frame, proposer) with the note that says why
it found nothing and, once the frame is submitted, the illusions it missed; and the proposals, their
masks as COCO RLE, and what the annotator made of them.
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None

FATES = ("pending", "accepted", "edited", "rejected")


def upgrade() -> None:
    op.create_table(
        "proposal_scans",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("frame_id", sa.Integer(), nullable=False),
        sa.Column("source", sa.String(32), nullable=False),
        sa.Column("content_sha256", sa.String(64), nullable=False),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column("seconds", sa.Double(), nullable=False),
        sa.Column("misses", sa.Integer(), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["frame_id"], ["frames.id"], name=op.f("fk_proposal_scans_frame_id_frames"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_proposal_scans")),
        sa.UniqueConstraint("frame_id", "source", name="uq_proposal_scans_frame_source"),
    )
    op.create_index("ix_proposal_scans_source", "proposal_scans", ["source"])
    op.create_table(
        "proposals",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("scan_id", sa.Integer(), nullable=False),
        sa.Column("frame_id", sa.Integer(), nullable=False),
        sa.Column("source", sa.String(32), nullable=False),
        sa.Column("rank", sa.Integer(), nullable=False),
        sa.Column("type_guess", sa.String(32), nullable=True),
        sa.Column("score", sa.Double(), nullable=False),
        sa.Column("illusion_rle", sa.JSON(), nullable=False),
        sa.Column("support_rle", sa.JSON(), nullable=False),
        sa.Column("fate", sa.Enum(*FATES, name="proposalfate", native_enum=False, create_constraint=True, length=32),
                  nullable=False),
        sa.Column("iou", sa.Double(), nullable=True),
        sa.Column("decided_by", sa.Integer(), nullable=True),
        sa.Column("decided_at", sa.DateTime(), nullable=True),
        sa.ForeignKeyConstraint(["scan_id"], ["proposal_scans.id"], name=op.f("fk_proposals_scan_id_proposal_scans"),
                                ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["frame_id"], ["frames.id"], name=op.f("fk_proposals_frame_id_frames"),
                                ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["decided_by"], ["users.id"], name=op.f("fk_proposals_decided_by_users"),
                                ondelete="SET NULL"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_proposals")),
    )
    op.create_index("ix_proposals_scan_id", "proposals", ["scan_id"])
    op.create_index("ix_proposals_frame_id", "proposals", ["frame_id"])
    op.create_index("ix_proposals_source_fate", "proposals", ["source", "fate"])


def downgrade() -> None:
    op.drop_table("proposals")
    op.drop_table("proposal_scans")
