"""Signed evidence: in-toto statements in DSSE envelopes, signed with an Ed25519 key kept outside the run.

``keys`` finds or creates the signing key and reads trusted public keys; ``dsse`` signs and verifies
envelopes; ``statement`` builds and reads the in-toto statements the campaign and ``uav-el verify`` sign.
"""

from assurance.attest.dsse import AttestationError

__all__ = ["AttestationError"]
