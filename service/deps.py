"""Dependencies shared by the routers."""

from fastapi import Request

from neural_asm.service.state import ServiceState


def get_state(request: Request) -> ServiceState:
    return request.app.state.service
