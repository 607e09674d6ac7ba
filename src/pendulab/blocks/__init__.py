"""Custom blocks in Python: a base class for user components and their build into FMUs (pythonfmu).

>>> from pendulab.blocks import Block, Var, build_block
"""

from pendulab.blocks.base import Block, Var, block_error
from pendulab.blocks.build import build_block, fix_model_description

__all__ = ["Block", "Var", "block_error", "build_block", "fix_model_description"]
