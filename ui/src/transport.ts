// The two ways to the drive's console, one interface: the server's WebSocket bridge
// (`regen ui`) and a serial port opened by the browser itself (Web Serial).

export interface Transport {
  /** What it is connected to, for the status bar. */
  readonly label: string;
  /** Text from the drive, as it arrives (not split into lines). */
  onText: (text: string) => void;
  /** The link ended; `why` in words. */
  onClose: (why: string) => void;
  send(text: string): void;
  close(): void;
}

export class WsTransport implements Transport {
  label: string;
  onText: (text: string) => void = () => {};
  onClose: (why: string) => void = () => {};
  private ws: WebSocket;
  private closing = false;

  private constructor(ws: WebSocket, label: string) {
    this.ws = ws;
    this.label = label;
    ws.onmessage = (e) => {
      if (typeof e.data === "string") this.onText(e.data);
    };
    ws.onclose = (e) => {
      if (!this.closing) this.onClose(`the bridge closed (code ${e.code}${e.reason ? ": " + e.reason : ""})`);
    };
  }

  /** Open `/ws` on this page's own server with the run's token. */
  static open(token: string): Promise<WsTransport> {
    const url = new URL("ws", location.href);
    url.protocol = location.protocol === "https:" ? "wss:" : "ws:";
    url.search = "?token=" + encodeURIComponent(token);
    url.hash = "";
    return new Promise((resolve, reject) => {
      const ws = new WebSocket(url);
      ws.onopen = () => resolve(new WsTransport(ws, `server bridge ${location.host}`));
      ws.onerror = () =>
        reject(new Error("the server refused the WebSocket (wrong token, another page already connected, or the server stopped)"));
    });
  }

  send(text: string): void {
    this.ws.send(text);
  }

  close(): void {
    this.closing = true;
    this.ws.close();
  }
}

/** The part of the Web Serial API used here (navigator.serial's port). */
export interface SerialPortLike {
  open(o: { baudRate: number }): Promise<void>;
  close(): Promise<void>;
  readable: ReadableStream<Uint8Array> | null;
  writable: WritableStream<Uint8Array> | null;
}

export class SerialTransport implements Transport {
  label = "serial port (Web Serial)";
  onText: (text: string) => void = () => {};
  onClose: (why: string) => void = () => {};
  private port: SerialPortLike;
  private writer: WritableStreamDefaultWriter<Uint8Array>;
  private reader: ReadableStreamDefaultReader<Uint8Array>;
  private enc = new TextEncoder();
  private closing = false;

  private constructor(port: SerialPortLike) {
    this.port = port;
    this.writer = port.writable!.getWriter();
    this.reader = port.readable!.getReader();
    void this.pump();
  }

  static async open(baudRate: number): Promise<SerialTransport> {
    const serial = (navigator as unknown as { serial?: { requestPort(): Promise<SerialPortLike> } }).serial;
    if (!serial) throw new Error("this browser has no Web Serial API (use Chromium or Edge, or the server bridge)");
    const port = await serial.requestPort();
    await port.open({ baudRate });
    return new SerialTransport(port);
  }

  private async pump(): Promise<void> {
    const dec = new TextDecoder();
    try {
      for (;;) {
        const { value, done } = await this.reader.read();
        if (done) break;
        if (value) this.onText(dec.decode(value, { stream: true }));
      }
      if (!this.closing) this.onClose("the serial port closed");
    } catch (e) {
      if (!this.closing) this.onClose(`the serial port failed: ${(e as Error).message}`);
    }
  }

  send(text: string): void {
    void this.writer.write(this.enc.encode(text));
  }

  close(): void {
    this.closing = true;
    void this.reader.cancel().catch(() => {});
    this.writer.releaseLock();
    void this.port.close().catch(() => {});
  }
}
