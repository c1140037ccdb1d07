"""pneumatic"""
