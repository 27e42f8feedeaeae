// The live stream (/api/stream, Server-Sent Events): one EventSource, one handler per message
// type. EventSource reconnects by itself; on reconnect the bridge sends the current state of
// everything first (its sticky messages), so the page never needs to ask.

export class Stream {
  /// handlers: {type: (data, receivedMs) => void}; onStatus(connected: bool).
  constructor(url, handlers, onStatus) {
    this.handlers = handlers;
    this.onStatus = onStatus;
    this.messages = 0;
    this.source = new EventSource(url);
    this.source.onopen = () => onStatus(true);
    this.source.onerror = () => onStatus(false);
    for (const type of Object.keys(handlers)) {
      this.source.addEventListener(type, (event) => {
        // Wall clock with sub-millisecond resolution, comparable with the bus's stamps.
        const receivedMs = performance.timeOrigin + performance.now();
        ++this.messages;
        let data;
        try {
          data = JSON.parse(event.data);
        } catch (e) {
          console.warn(`stream: malformed ${type} message`, e);
          return;
        }
        handlers[type](data, receivedMs);
      });
    }
  }

  close() {
    this.source.close();
  }
}
