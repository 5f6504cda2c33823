"""Shared object knowledge (motion profiles, ...), used by apps that never import each other."""
