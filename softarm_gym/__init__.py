"""softarm-gym: Gymnasium environments for multi-section pneumatic soft arms."""

__version__ = "0.1.0"
