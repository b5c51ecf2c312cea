"""Serenity."""
