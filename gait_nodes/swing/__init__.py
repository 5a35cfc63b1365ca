"""Swing-leg planning: value iteration, table files, policy lookup, polynomial swings."""
