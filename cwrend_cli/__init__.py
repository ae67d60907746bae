"""cwrend: robust low-thrust rendezvous campaigns (Candan & Servadio, AAS 26-893)."""

__version__ = "0.2.0"
